"""The deformation prior: hand-worked values, gradients, and points far from the mesh (docs/architecture.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from models.avatars.codynerf.prior import PriorMeshes, deformation_prior, nearest_vertices

D = torch.float64


def meshes() -> PriorMeshes:
    """Three vertices. Canonical at x = 0, 1, 2 on the x axis; the expression lifts vertex 1 by 0.1 in y;
    the pose then shifts everything by +1 in z."""
    canonical = torch.tensor([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]], dtype=D)
    expressed = canonical + torch.tensor([[0.0, 0, 0], [0.0, 0.1, 0], [0.0, 0, 0]], dtype=D)
    posed = expressed + torch.tensor([0.0, 0.0, 1.0], dtype=D)
    normals = torch.tensor([[0.0, 0, 1]] * 3, dtype=D)
    return PriorMeshes(canonical, expressed, posed, normals)


def test_hand_worked():
    m = meshes()
    # A point 0.03 m above vertex 1 (posed at (1, 0.1, 1)): its nearest vertex is 1, distance 0.03.
    x = torch.tensor([[1.0, 0.13, 1.0]], dtype=D)
    p = deformation_prior(x, m, falloff_m=0.05)
    assert p.nearest.tolist() == [1]
    torch.testing.assert_close(p.distance, torch.tensor([0.03], dtype=D))
    # Canonical - posed at vertex 1 = (0, -0.1, -1); decay exp(-0.03 / 0.05) = exp(-0.6) = 0.548812.
    decay = math.exp(-0.6)
    torch.testing.assert_close(p.offset, torch.tensor([[0.0, -0.1 * decay, -1.0 * decay]], dtype=D))
    torch.testing.assert_close(p.expression_offset, torch.tensor([[0.0, -0.1 * decay, 0.0]], dtype=D))
    torch.testing.assert_close(p.pose_offset, torch.tensor([[0.0, 0.0, -1.0 * decay]], dtype=D))


def test_on_the_mesh_the_prior_maps_to_canonical():
    m = meshes()
    p = deformation_prior(m.posed.clone(), m)
    torch.testing.assert_close(m.posed + p.offset, m.canonical)


def test_nearest_matches_brute_force():
    g = torch.Generator().manual_seed(0)
    v = torch.rand(500, 3, generator=g, dtype=D)
    x = torch.rand(2000, 3, generator=g, dtype=D) * 1.4 - 0.2
    brute = torch.cdist(x, v).argmin(1)
    assert torch.equal(nearest_vertices(x, v), brute)


@pytest.mark.parametrize("far", [10.0, 1e3, 1e6])
def test_far_points_finite_zero_prior_finite_gradients(far):
    m = meshes()
    x = torch.tensor([[far, 0.0, 0.0], [0.0, -far, far], [1.0, 0.1, 1.0]], dtype=D, requires_grad=True)
    p = deformation_prior(x, m)
    assert torch.isfinite(p.offset).all() and torch.isfinite(p.distance).all()
    assert p.offset[:2].abs().max() < 1e-30 * far  # nothing reaches that far
    (p.offset.sum() + p.distance.sum()).backward()
    assert torch.isfinite(x.grad).all()
    # The third point sits exactly on vertex 1: distance 0, a finite gradient there too.
    assert p.distance[2] < 1e-8


def test_gradcheck_prior_in_points_and_meshes():
    m = meshes()
    posed = m.posed.clone().requires_grad_()
    x = torch.tensor([[0.9, 0.2, 1.05], [2.1, -0.05, 0.97]], dtype=D, requires_grad=True)

    def f(x, posed):
        return deformation_prior(x, PriorMeshes(m.canonical, m.expressed, posed, m.normals), 0.1).offset

    assert torch.autograd.gradcheck(f, (x, posed))


def test_non_finite_points_do_not_break_the_search():
    m = meshes()
    x = torch.tensor([[np.nan, 0.0, 0.0], [np.inf, 1.0, 1.0]], dtype=D)
    assert nearest_vertices(x, m.posed).shape == (2,)
