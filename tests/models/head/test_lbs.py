"""Skinning math: hand-worked values, an independent rotation reference, float64 gradcheck, batching."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from models.head.lbs import lbs, rigid_transforms, rotation_matrix_from_axis_angle


def test_rotation_hand_worked():
    # 90 degrees about z: x -> y, y -> -x.
    R = rotation_matrix_from_axis_angle(torch.tensor([0.0, 0.0, math.pi / 2], dtype=torch.float64))
    expected = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    torch.testing.assert_close(R, expected, atol=1e-12, rtol=0)


@pytest.mark.parametrize("batch_shape", [(1,), (7,), (2, 3)])
def test_rotation_matches_scipy(batch_shape):
    rng = np.random.default_rng(0)
    vecs = rng.normal(0, 1.5, (*batch_shape, 3))
    vecs.reshape(-1, 3)[0] = [0.0, 0.0, 0.0]
    vecs.reshape(-1, 3)[-1] = [np.pi, 0, 0]
    ours = rotation_matrix_from_axis_angle(torch.as_tensor(vecs)).numpy()
    ref = Rotation.from_rotvec(vecs.reshape(-1, 3)).as_matrix().reshape(*batch_shape, 3, 3)
    np.testing.assert_allclose(ours, ref, atol=1e-12)


@pytest.mark.parametrize("vec", [[0.3, -0.2, 0.5], [1e-6, 2e-6, -1e-6], [0.0, 0.0, 0.0], [3.0, 0.5, 0.1]])
def test_rotation_gradcheck(vec):
    x = torch.tensor(vec, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(rotation_matrix_from_axis_angle, (x,), eps=1e-7, atol=1e-6)


def _toy():
    """Two joints: the root at vertex 0, a child at vertex 2; vertex 0 on the root, vertex 1 on the child,
    vertex 2 half on each."""
    template = torch.tensor([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.5, 1.0, 0.0]], dtype=torch.float64)
    J_regressor = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    weights = torch.tensor([[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]], dtype=torch.float64)
    empty = torch.zeros(3, 3, 0, dtype=torch.float64)
    return template, J_regressor, weights, empty


def test_lbs_hand_worked():
    template, J_reg, weights, empty = _toy()
    # Joint 1 sits at vertex 2 = (0.5, 1, 0). Turn the child by 90 degrees about z.
    pose = torch.tensor([[[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2]]], dtype=torch.float64)
    verts, joints = lbs(torch.zeros(1, 0, dtype=torch.float64), torch.zeros(1, 0, dtype=torch.float64), pose,
                        template, empty, empty, empty, J_reg, [-1, 0], weights)
    # Vertex 0 is on the root: unmoved. Vertex 1 = J1 + Rz(90)(v - J1) = (0.5,1,0) + Rz(90)(-0.5,1,0)
    #   = (0.5,1,0) + (-1,-0.5,0) = (-0.5, 0.5, 0).
    # Vertex 2 is the joint itself: both transforms leave it in place.
    expected = torch.tensor([[1.0, 0.0, 0.0], [-0.5, 0.5, 0.0], [0.5, 1.0, 0.0]], dtype=torch.float64)
    torch.testing.assert_close(verts[0], expected, atol=1e-12, rtol=0)
    torch.testing.assert_close(joints[0], torch.tensor([[1.0, 0, 0], [0.5, 1, 0]], dtype=torch.float64))


def test_rigid_transforms_chain():
    # Root turned 90 degrees about z carries the child joint at (1,0,0) to (0,1,0).
    rot = rotation_matrix_from_axis_angle(torch.tensor([[[0, 0, math.pi / 2], [0, 0, 0]]], dtype=torch.float64))
    joints = torch.tensor([[[0.0, 0, 0], [1.0, 0, 0]]], dtype=torch.float64)
    posed, _A = rigid_transforms(rot, joints, [-1, 0])
    torch.testing.assert_close(posed[0, 1], torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), atol=1e-12,
                               rtol=0)


def test_lbs_gradcheck():
    rng = np.random.default_rng(1)
    V, J, S, E = 6, 3, 2, 2
    t = lambda a: torch.as_tensor(a, dtype=torch.float64)
    template = t(rng.normal(0, 0.1, (V, 3)))
    shape_basis, expr_basis = t(rng.normal(0, 0.01, (V, 3, S))), t(rng.normal(0, 0.01, (V, 3, E)))
    pose_basis = t(rng.normal(0, 0.01, (V, 3, (J - 1) * 9)))
    J_reg = t(rng.dirichlet(np.ones(V), J))
    weights = t(rng.dirichlet(np.ones(J), V))
    inputs = (t(rng.normal(0, 1, (2, S))).requires_grad_(), t(rng.normal(0, 1, (2, E))).requires_grad_(),
              t(rng.normal(0, 0.5, (2, J, 3))).requires_grad_())
    f = lambda s, e, p: lbs(s, e, p, template, shape_basis, expr_basis, pose_basis, J_reg, [-1, 0, 1], weights)
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6)


def test_batch_equals_singles(builtin_model):
    from models.head.head import Head

    head = Head(builtin_model, dtype=torch.float64)
    rng = np.random.default_rng(2)
    B = 4
    args = {"shape": torch.as_tensor(rng.normal(0, 1, (B, builtin_model.num_shape))),
            "expression": torch.as_tensor(rng.uniform(0, 1, (B, builtin_model.num_expression))),
            "full_pose": torch.as_tensor(rng.normal(0, 0.3, (B, 5, 3))),
            "translation": torch.as_tensor(rng.normal(0, 0.1, (B, 3)))}
    v, _j, lm = head(**args)
    for b in range(B):
        vb, _jb, lb = head(**{k: a[b : b + 1] for k, a in args.items()})
        torch.testing.assert_close(v[b : b + 1], vb, atol=1e-12, rtol=0)
        torch.testing.assert_close(lm[b : b + 1], lb, atol=1e-12, rtol=0)
