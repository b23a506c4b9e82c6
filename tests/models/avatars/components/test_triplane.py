"""Tri-plane features against a bilinear lookup written out by hand, their gradients (float64 gradcheck), and a
hand-worked texel."""

from __future__ import annotations

import numpy as np
import torch

from models.avatars.components.triplane import PLANE_AXES, TriPlane, triplane_lookup


def bilinear_reference(plane: np.ndarray, a: float, b: float) -> np.ndarray:
    """(C,) plane (C,R,R) read at (a, b) in [-1, 1] (a along columns, b along rows; texel centres at the ends)."""
    R = plane.shape[1]
    x, y = (np.clip(a, -1, 1) + 1) / 2 * (R - 1), (np.clip(b, -1, 1) + 1) / 2 * (R - 1)
    x0, y0 = min(int(np.floor(x)), R - 2), min(int(np.floor(y)), R - 2)
    fx, fy = x - x0, y - y0
    return ((1 - fx) * (1 - fy) * plane[:, y0, x0] + fx * (1 - fy) * plane[:, y0, x0 + 1]
            + (1 - fx) * fy * plane[:, y0 + 1, x0] + fx * fy * plane[:, y0 + 1, x0 + 1])


def test_lookup_matches_a_bilinear_reference_inside_and_beyond_the_box():
    g = torch.Generator().manual_seed(0)
    planes = torch.randn(3, 4, 7, 7, generator=g, dtype=torch.float64)
    u = torch.rand(50, 3, generator=g, dtype=torch.float64) * 2.4 - 1.2  # some beyond [-1, 1]: the border's
    got = triplane_lookup(planes, u).numpy()
    for i, p in enumerate(u.numpy()):
        want = np.concatenate([bilinear_reference(planes[k].numpy(), p[a], p[b])
                               for k, (a, b) in enumerate(PLANE_AXES)])
        np.testing.assert_allclose(got[i], want, atol=1e-12)


def test_a_texel_centre_reads_the_texel():
    # a 5x5 xy plane, the point (x, y) = (0.5, -1) in box units: column (0.5 + 1) / 2 * 4 = 3, row 0
    tp = TriPlane(torch.zeros(3), torch.ones(3) * 2, resolution=5, features=1)
    with torch.no_grad():
        tp.planes.zero_()
        tp.planes[0, 0, 0, 3] = 7.0
    x = torch.tensor([[1.5, 0.0, 1.0]])  # box [0, 2]: u = x - 1 = (0.5, -1, 0)
    np.testing.assert_allclose(tp(x)[0, 0].item(), 7.0)


def test_gradients_against_finite_differences():
    g = torch.Generator().manual_seed(1)
    planes = torch.randn(3, 2, 5, 5, generator=g, dtype=torch.float64, requires_grad=True)
    u = (torch.rand(6, 3, generator=g, dtype=torch.float64) * 1.8 - 0.9).requires_grad_(True)
    assert torch.autograd.gradcheck(triplane_lookup, (planes, u), eps=1e-6, atol=1e-6)
