"""Hard cases for the head models, on every kind of head model (the built-in head, a generated FLAME
file, ICT-FaceKit where ../shared has it): rotations at 0, 1e-8, pi - 1e-6, pi, 2 pi about every joint (both
eyes); expression weights of +-10; random controls swept by hypothesis (finite outputs and gradients, small
changes move vertices a little); NaN and huge controls refused where they come in."""

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
def flame_head_model(tmp_path_factory, builtin_model):
    from models.head.sources import load_head
    from tests.models.head.flame_files import write_flame_from_head

    return load_head(f"flame:{write_flame_from_head(tmp_path_factory.mktemp('flame'), builtin_model)}")


@pytest.fixture(scope="module", params=["builtin", "flame", "ict"])
def head(request, builtin_model):
    model = {"builtin": lambda: builtin_model, "flame": lambda: request.getfixturevalue("flame_head_model"),
             "ict": lambda: request.getfixturevalue("ict_model")}[request.param]()
    return Head(model, dtype=torch.float64)


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
@pytest.mark.parametrize("joint", [0, 1, 2, 3, 4])
def test_rotations_finite_with_finite_gradients(head, joint, angle, axis):
    if joint >= head.model.num_joints:
        pytest.skip(f"{head.model.name} has {head.model.num_joints} joints")
    pose = torch.zeros(1, head.model.num_joints, 3, dtype=torch.float64)
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
    pose = torch.zeros(1, head.model.num_joints, 3, dtype=torch.float64)
    pose[0, 0, 1] = math.pi
    verts, _joints, _ = head(**_inputs(head, pose=pose))
    rest, rest_joints, _ = head(**_inputs(head))
    c = rest_joints[0, 0]
    expected = (rest[0] - c) * torch.tensor([-1.0, 1.0, -1.0], dtype=torch.float64) + c
    torch.testing.assert_close(verts[0], expected, atol=1e-9, rtol=0)


@pytest.mark.parametrize("weight", [-10.0, 10.0])
def test_extreme_expressions_finite(head, weight):
    expr = torch.full((1, head.model.num_expression), weight, dtype=torch.float64, requires_grad=True)
    pose = torch.zeros(1, head.model.num_joints, 3, dtype=torch.float64)
    pose[0, min(2, head.model.num_joints - 1), 0] = 1.0
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


@settings(max_examples=40, deadline=None)
@given(
    expr=st.lists(control, min_size=60, max_size=60),
    shape=st.lists(control, min_size=12, max_size=12),
    pose=st.lists(rotation, min_size=15, max_size=15),
    direction=st.integers(0, 10_000),
    step=st.floats(1e-6, 1e-3),
)
def test_random_controls_finite_and_continuous(head, expr, shape, pose, direction, step):
    """Any controls (every expression, the first 12 identity coefficients, every joint): finite vertices and
    finite gradients; a small step along one of them moves every vertex at most as far as the model allows."""
    m = head.model
    E, S, J = m.num_expression, min(m.num_shape, 12), m.num_joints
    base = torch.tensor(expr[:E] + [0.0] * max(0, E - 60) + shape[:S] + pose[:3 * J], dtype=torch.float64)

    def run(vec):
        full_shape = torch.zeros(1, m.num_shape, dtype=torch.float64)
        full_shape[0, :S] = vec[E:E + S]
        return head(shape=full_shape, expression=vec[None, :E], full_pose=vec[E + S:].reshape(1, J, 3),
                     translation=torch.zeros(1, 3, dtype=torch.float64))

    leaf = base.clone().requires_grad_(True)
    v0, joints0, lmks = run(leaf)
    assert torch.isfinite(v0).all() and torch.isfinite(lmks).all()
    (grad,) = torch.autograd.grad(v0.square().sum() + lmks.sum(), leaf)
    assert torch.isfinite(grad).all()
    v0, joints0 = v0.detach(), joints0.detach()
    k = direction % len(base)
    moved = base.clone()
    moved[k] += step
    v1 = run(moved)[0]
    per_coeff = _per_coefficient_bound(head)
    reach = torch.cdist(v0[0], joints0[0]).max().item()  # of this shaped, posed head
    # Changing one axis-angle component by `step` turns that joint's frame by at most `step` radians (exp is
    # 1-Lipschitz on SO(3)), so every point carried by it moves at most (its distance to the joint) * step.
    # A coefficient step moves the shaped vertices by at most per_coeff * step, and the rest joints (convex
    # combinations of vertices) as much; each of the <= 3 rotated joints above a vertex turns its pivot's
    # shift by (I - R), adding at most 2 * per_coeff * step each.
    bound = step * (per_coeff * (1 + 2 * 3) if k < E + S else reach)
    assert (v1 - v0).norm(dim=-1).max().item() <= bound * (1 + 1e-6) + 1e-12


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 1e30])
def test_nan_inf_and_huge_controls_are_refused_where_they_come_in(bad):
    """Controls enter from files (--controls, the dataset's frames): refused there, not rendered as garbage."""
    from models.head.controls import ControlsError, controls_from_dict

    for data in ({"expression": [0.0, bad]}, {"pose": {"jaw": [bad, 0.0, 0.0]}}, {"gaze": {"right": [0.0, bad, 0.0]}},
                 {"translation": [0.0, 0.0, bad]}, {"shape": [bad]}):
        with pytest.raises(ControlsError):
            controls_from_dict(data)
