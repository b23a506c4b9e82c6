"""Hard cases for the head models (DESIGN 6): rotations at 0, 1e-8, pi - 1e-6, pi, 2 pi; expression
weights of +-10; random controls swept by hypothesis (finite outputs, small changes move vertices a
little)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from models.head.head import Head

ANGLES = {"zero": 0.0, "1e-8": 1e-8, "pi-1e-6": math.pi - 1e-6, "pi": math.pi, "2pi": 2 * math.pi}
AXES = {"x": [1.0, 0.0, 0.0], "oblique": [0.48, -0.6, 0.64]}


@pytest.fixture(scope="module")
def head(builtin_model):
    return Head(builtin_model, dtype=torch.float64)


def _inputs(head, pose=None, expression=None):
    m = head.model
    return {
        "shape": torch.zeros(1, m.num_shape, dtype=torch.float64),
        "expression": torch.zeros(1, m.num_expression, dtype=torch.float64) if expression is None else expression,
        "full_pose": torch.zeros(1, m.num_joints, 3, dtype=torch.float64) if pose is None else pose,
        "translation": torch.zeros(1, 3, dtype=torch.float64),
    }


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("joint", [0, 1, 2, 3])
def test_rotations_finite_with_finite_gradients(head, joint, angle, axis):
    pose = torch.zeros(1, 5, 3, dtype=torch.float64)
    pose[0, joint] = ANGLES[angle] * torch.tensor(AXES[axis], dtype=torch.float64)
    pose.requires_grad_(True)
    verts, _joints, lmks = head(**_inputs(head, pose=pose))
    assert torch.isfinite(verts).all() and torch.isfinite(lmks).all()
    (grad,) = torch.autograd.grad(verts.square().sum() + lmks.sum(), pose)
    assert torch.isfinite(grad).all()
    if angle in ("zero", "1e-8", "2pi"):
        rest = head(**_inputs(head))[0]
        torch.testing.assert_close(verts, rest, atol=1e-7, rtol=0)  # 2 pi turns all the way round


def test_half_turn_about_y_mirrors_about_the_joint(head):
    """A root rotation of exactly pi about +y maps (x, y, z) to (-x, y, -z) about the root joint."""
    pose = torch.zeros(1, 5, 3, dtype=torch.float64)
    pose[0, 0, 1] = math.pi
    verts, _joints, _ = head(**_inputs(head, pose=pose))
    rest, rest_joints, _ = head(**_inputs(head))
    c = rest_joints[0, 0]
    expected = (rest[0] - c) * torch.tensor([-1.0, 1.0, -1.0], dtype=torch.float64) + c
    torch.testing.assert_close(verts[0], expected, atol=1e-9, rtol=0)


@pytest.mark.parametrize("weight", [-10.0, 10.0])
def test_extreme_expressions_finite(head, weight):
    expr = torch.full((1, head.model.num_expression), weight, dtype=torch.float64, requires_grad=True)
    pose = torch.zeros(1, 5, 3, dtype=torch.float64)
    pose[0, 2, 0] = 1.0
    verts, _, lmks = head(**_inputs(head, pose=pose, expression=expr))
    assert torch.isfinite(verts).all() and torch.isfinite(lmks).all()
    (g,) = torch.autograd.grad(verts.sum(), expr)
    assert torch.isfinite(g).all()


def _per_coefficient_bound(head) -> float:
    """Metres a vertex can move per unit of one expression or shape coefficient (before rotation)."""
    m = head.model
    return float(max(np.linalg.norm(m.expr_basis, axis=1).max(), np.linalg.norm(m.shape_basis, axis=1).max()))


control = st.floats(-3, 3, allow_nan=False)
rotation = st.floats(-math.pi, math.pi, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(
    expr=st.lists(control, min_size=16, max_size=16),
    shape=st.lists(control, min_size=12, max_size=12),
    pose=st.lists(rotation, min_size=15, max_size=15),
    direction=st.integers(0, 16 + 12 + 15 - 1),
    step=st.floats(1e-6, 1e-3),
)
def test_random_controls_finite_and_continuous(head, expr, shape, pose, direction, step):
    base = torch.tensor(expr + shape + pose, dtype=torch.float64)

    def run(vec):
        return head(shape=vec[None, 16:28], expression=vec[None, :16], full_pose=vec[28:].reshape(1, 5, 3),
                    translation=torch.zeros(1, 3, dtype=torch.float64))

    v0, joints0, _ = run(base)
    assert torch.isfinite(v0).all()
    moved = base.clone()
    moved[direction] += step
    v1 = run(moved)[0]
    per_coeff = _per_coefficient_bound(head)
    reach = torch.cdist(v0[0], joints0[0]).max().item()  # of this shaped, posed head
    # Changing one axis-angle component by `step` turns that joint's frame by at most `step` radians (exp is
    # 1-Lipschitz on SO(3)), so every point carried by it moves at most (its distance to the joint) * step.
    # A coefficient step moves the shaped vertices by at most per_coeff * step, and the rest joints (convex
    # combinations of vertices) as much; each of the <= 3 rotated joints above a vertex turns its pivot's
    # shift by (I - R), adding at most 2 * per_coeff * step each.
    bound = step * (per_coeff * (1 + 2 * 3) if direction < 28 else reach)
    assert (v1 - v0).norm(dim=-1).max().item() <= bound * (1 + 1e-6) + 1e-12
