"""Volume rendering: hand-worked values, float64 gradcheck, and the hard cases of docs/architecture.md."""

from __future__ import annotations

import math

import pytest
import torch

from render.volume import (
    alpha_from_density,
    composite,
    expected_depth,
    ray_aabb_intersect,
    sample_pdf,
    weights_from_density,
)

D = torch.float64


def test_weights_hand_worked():
    # Three samples of length 0.5 with densities 0, 2 ln 2, 2 ln 2:
    # alpha = 0, 1 - exp(-ln 2) = 1/2, 1/2; T = 1, 1, 1/2; w = 0, 1/2, 1/4; 1/4 of the light passes.
    sig = torch.tensor([[0.0, 2 * math.log(2), 2 * math.log(2)]], dtype=D)
    w, rest = weights_from_density(sig, torch.full_like(sig, 0.5))
    torch.testing.assert_close(w, torch.tensor([[0.0, 0.5, 0.25]], dtype=D))
    torch.testing.assert_close(rest, torch.tensor([0.25], dtype=D))
    # Colours red, green, blue and a white background: 1/2 green + 1/4 blue + 1/4 white.
    rgb = torch.tensor([[[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]], dtype=D)
    out = composite(w, rgb, rest, torch.ones(3, dtype=D))
    torch.testing.assert_close(out, torch.tensor([[0.25, 0.75, 0.5]], dtype=D))
    # Depth: (1/2 * 0.75 + 1/4 * 1.25) / (3/4) = 0.6875 / 0.75 = 0.91667 at midpoints 0.25, 0.75, 1.25.
    torch.testing.assert_close(expected_depth(w, torch.tensor([[0.25, 0.75, 1.25]], dtype=D)),
                               torch.tensor([0.6875 / 0.75], dtype=D))


def test_weights_and_rest_sum_to_one():
    g = torch.Generator().manual_seed(0)
    sig = torch.rand(50, 32, generator=g, dtype=D) * 30
    dt = torch.rand(50, 32, generator=g, dtype=D) * 0.05
    w, rest = weights_from_density(sig, dt)
    torch.testing.assert_close(w.sum(-1) + rest, torch.ones(50, dtype=D))


def test_gradcheck_compositing():
    g = torch.Generator().manual_seed(1)
    sig = (torch.rand(3, 5, generator=g, dtype=D) * 4).requires_grad_()
    dt = (torch.rand(3, 5, generator=g, dtype=D) * 0.3 + 0.01).requires_grad_()
    rgb = torch.rand(3, 5, 3, generator=g, dtype=D).requires_grad_()
    bg = torch.rand(3, generator=g, dtype=D).requires_grad_()

    def f(sig, dt, rgb, bg):
        w, rest = weights_from_density(sig, dt)
        return composite(w, rgb, rest, bg)

    assert torch.autograd.gradcheck(f, (sig, dt, rgb, bg))


def test_gradcheck_importance_sampling():
    """Sample positions depend smoothly on bins and weights away from the cdf's steps (fixed quantiles)."""
    g = torch.Generator().manual_seed(2)
    bins = torch.cumsum(torch.rand(2, 7, generator=g, dtype=D) + 0.1, -1).requires_grad_()
    weights = (torch.rand(2, 6, generator=g, dtype=D) + 0.1).requires_grad_()
    assert torch.autograd.gradcheck(lambda b, w: sample_pdf(b, w, 5), (bins, weights))


def test_importance_sampling_follows_the_weights():
    # All weight in the second of four unit bins: every sample lands in [1, 2].
    bins = torch.tensor([[0.0, 1.0, 2.0, 3.0, 4.0]], dtype=D)
    t = sample_pdf(bins, torch.tensor([[0.0, 1.0, 0.0, 0.0]], dtype=D), 8, eps=0.0)
    assert ((t >= 1.0) & (t <= 2.0)).all()
    # Even quantiles of a uniform pdf are evenly spaced: (k + 0.5) / 8 * 4.
    t = sample_pdf(bins, torch.ones(1, 4, dtype=D), 8)
    torch.testing.assert_close(t[0], (torch.arange(8, dtype=D) + 0.5) / 2)
    # Random samples are sorted and reproducible with the same generator.
    a = sample_pdf(bins, torch.rand(1, 4, dtype=D), 16, torch.Generator().manual_seed(3))
    b = sample_pdf(bins, torch.rand(1, 4, dtype=D), 16, torch.Generator().manual_seed(3))
    assert (a.diff() >= 0).all() and a.shape == b.shape


def test_ray_box_hand_worked():
    o = torch.tensor([[0.0, 0.0, 5.0], [0.0, 0.0, 5.0], [3.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 5.0]], dtype=D)
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]],
                     dtype=D)
    t0, t1, hit = ray_aabb_intersect(o, d, -torch.ones(3, dtype=D), torch.ones(3, dtype=D))
    # Straight in along -z from z=5: enters at 4, leaves at 6. Parallel to the box, outside: a miss.
    # From x=3 along -x: 2..4. From the centre: starts inside (0) to 1. Along the box's edge x=y=1: grazes 4..6.
    assert hit.tolist() == [True, False, True, True, True]
    torch.testing.assert_close(t0, torch.tensor([4.0, 0.0, 2.0, 0.0, 4.0], dtype=D))
    torch.testing.assert_close(t1, torch.tensor([6.0, 0.0, 4.0, 1.0, 6.0], dtype=D))


@pytest.mark.parametrize("density", [0.0, 1e-12, 1.0, 1e3, 1e6])
def test_hard_densities_stay_finite(density):
    sig = torch.full((4, 16), density, dtype=torch.float32, requires_grad=True)
    dt = torch.full((4, 16), 0.01, dtype=torch.float32, requires_grad=True)
    rgb = torch.rand(4, 16, 3, requires_grad=True)
    w, rest = weights_from_density(sig, dt)
    out = composite(w, rgb, rest, torch.ones(3))
    out.sum().backward()
    for t in (out, sig.grad, dt.grad, rgb.grad):
        assert torch.isfinite(t).all()
    if density == 1e6:  # opaque at the first sample: its colour alone
        torch.testing.assert_close(out, rgb[:, 0].detach())


def test_alpha_precision_for_tiny_products():
    # 1 - exp(-1e-10) loses everything in float32 as written; -expm1 keeps it.
    a = alpha_from_density(torch.tensor([1e-8]), torch.tensor([1e-2]))
    torch.testing.assert_close(a, torch.tensor([1e-10]), rtol=1e-4, atol=0)


def test_zero_weight_rays_sample_uniformly_and_depth_is_finite():
    bins = torch.linspace(1, 2, 9, dtype=D)[None]
    t = sample_pdf(bins, torch.zeros(1, 8, dtype=D), 4)
    torch.testing.assert_close(t[0], torch.tensor([1.125, 1.375, 1.625, 1.875], dtype=D))
    assert torch.isfinite(expected_depth(torch.zeros(1, 8, dtype=D), bins[:, 1:])).all()
