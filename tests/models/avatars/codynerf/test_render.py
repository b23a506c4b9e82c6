"""CoDyNeRF's rendering steps, each shortcut against its exact reference on the shipped demo avatar (a real,
trained checkpoint): the early stop within stop_below of every sample evaluated, the colour skip within the
weight it skips, both actually skipping work; a second pass that only adds samples; and the exact path's
compositing differentiated in float64 (gradcheck), as training takes it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from models.avatars.codynerf import render
from models.avatars.codynerf.field import FieldOutput
from models.avatars.codynerf.prior import PriorSamples
from models.avatars.registry import load_avatar
from models.avatars.rendering import pixel_rays_of
from models.head.controls import Controls
from render.camera import framing_camera
from render.gl.raster import Rasterizer
from render.rays import Rays
from render.sampling import RaySamples
from render.volume import composite
from tests.conftest import CODYNERF_DEMO

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def scene(gl):
    """The demo avatar, a head-on frame's geometry (with its shadow map), and the rays of the pixels it renders."""
    avatar, _ = load_avatar(CODYNERF_DEMO)
    r = Rasterizer(gl)
    geo = avatar.frame_geometry(Controls(), r)
    cam = framing_camera(avatar.head_model.template, 20.0, 5.0, fov_y_deg=18.0, width_px=48, height_px=48)
    rays, _ = pixel_rays_of(avatar, geo, cam, r)
    r.release()
    return avatar, geo, rays


def trace(avatar, geo, rays: Rays, **settings):
    cfg = avatar.render_cfg
    s = render.RaySettings(cfg.samples_per_ray, cfg.shell_m, **settings)
    omega, phi = avatar.codes(None)
    with torch.no_grad():
        return avatar.trace(rays, geo, omega, phi, s)


def test_early_stop_is_within_stop_below_of_the_exact_image(scene):
    """A stopped ray drops its back half: what that half added (weights summing to the light T <= stop that its
    front half let through, times colours in [0, 1]) and the background it let through, together T times
    colours in [0, 1]: the error is at most stop_below. On the demo avatar the display's 1e-3 never stops a ray
    (measured: after the front half, which ends at the rasterized surface, the median ray still carries 40% of
    its light), so the bound is checked at 0.1 and 0.3, where rays do stop."""
    avatar, geo, rays = scene
    exact = trace(avatar, geo, rays)
    for stop in (0.1, 0.3):
        fast = trace(avatar, geo, rays, stop_below=stop)
        err = (fast.buffers["rgb"] - exact.buffers["rgb"]).abs().max()
        assert float(err) <= stop + 1e-6, (stop, float(err))
        assert len(fast.internals.densities.keep) < len(exact.internals.densities.keep)  # work was skipped
    same = trace(avatar, geo, rays, stop_below=1e-3)
    assert len(same.internals.densities.keep) == len(exact.internals.densities.keep)
    torch.testing.assert_close(same.buffers["rgb"], exact.buffers["rgb"], atol=1e-6, rtol=0)


def test_colour_skip_is_within_the_weight_it_skips(scene):
    avatar, geo, rays = scene
    exact = trace(avatar, geo, rays)
    for m in (1e-4, 1e-2):
        fast = trace(avatar, geo, rays, min_weight=m)
        weights = fast.internals.weights
        # Each skipped sample would have added weight * colour (< m) to its pixel.
        skipped = weights * (weights <= m)
        bound = skipped.sum(-1, keepdim=True)
        err = (fast.buffers["rgb"] - exact.buffers["rgb"]).abs()
        assert (err <= bound + 1e-6).all()
        assert fast.internals.shown.which is not None
        assert len(fast.internals.shown.which) < len(fast.internals.densities.keep)
        torch.testing.assert_close(fast.buffers["opacity"], exact.buffers["opacity"])  # only colour is skipped


def test_fine_pass_keeps_the_first_pass_samples(scene):
    avatar, geo, rays = scene
    first = trace(avatar, geo, rays)
    fine = trace(avatar, geo, rays, fine=6)
    S = first.internals.samples.t_starts.shape[1]
    assert fine.internals.samples.t_starts.shape[1] == S + 6
    mids = fine.internals.samples.t_mid
    assert (fine.internals.samples.deltas >= 0).all()
    assert (mids[:, 1:] >= mids[:, :-1] - 1e-6).all()
    assert np.isfinite(fine.buffers["rgb"].numpy()).all()


def test_display_settings_come_from_the_render_config(scene):
    avatar, _, _ = scene
    s = avatar.settings(training=False)
    cfg = avatar.render_cfg
    assert (s.stop_below, s.min_weight, s.fine) == (cfg.stop_below, cfg.min_weight, cfg.fine_samples)
    t = avatar.settings(training=True, create_graph=True)
    assert (t.stop_below, t.min_weight, t.fine, t.skip_empty, t.create_graph) == (0.0, 0.0, 0, False, True)
    avatar.render_cfg = replace(cfg, dense_samples=64)
    try:  # the dense reference: every pixel's ray across the box, no shortcut
        d = avatar.settings(training=False)
        assert (d.dense, d.stop_below, d.min_weight, d.fine) == (64, 0.0, 0.0, 0)
    finally:
        avatar.render_cfg = cfg


def test_exact_compositing_gradients_by_gradcheck():
    """Density and colour at N evaluated samples of R rays, scattered to (R,S), composited (Eq. 1): the
    gradients the exact path trains with, against finite differences in float64."""
    R, S = 2, 4
    keep = torch.tensor([0, 2, 3, 5, 6])  # samples 1, 4 and 7 lie outside the support (density exactly 0)
    t = torch.linspace(0.0, 0.08, S + 1, dtype=torch.float64)
    samples = RaySamples(t[:-1].expand(R, S), t[1:].expand(R, S), torch.ones(R, dtype=torch.bool))
    zeros = torch.zeros(len(keep), dtype=torch.float64)
    prior = PriorSamples(keep, zeros, zeros[:, None].expand(-1, 3), zeros[:, None].expand(-1, 3),
                         zeros[:, None].expand(-1, 3), zeros[:, None].expand(-1, 3))

    def image(sigma: torch.Tensor, rgb: torch.Tensor) -> torch.Tensor:
        d = render.Densities(keep, prior, FieldOutput(sigma, rgb, rgb), torch.ones_like(sigma))
        _, weights, remaining = render.weights_of(d, samples)
        shown = render.Shown(None, d.field, prior, keep, rgb, keep, (R, S))
        colour = shown.to_rays(torch.sigmoid(rgb))
        return composite(weights, colour, remaining, torch.tensor([1.0, 0.5, 0.0], dtype=torch.float64))

    g = torch.Generator().manual_seed(0)
    sigma = (torch.rand(len(keep), generator=g, dtype=torch.float64) * 80).requires_grad_(True)
    rgb = torch.randn(len(keep), 3, generator=g, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(image, (sigma, rgb))
    # Hand-worked: one sample of density 50/m over 2 cm lets through exp(-1) of the light.
    one = render.Densities(torch.tensor([0]), prior.take(torch.tensor([0])),
                           FieldOutput(torch.tensor([50.0], dtype=torch.float64), rgb[:1], rgb[:1]),
                           torch.ones(1, dtype=torch.float64))
    _, w, rem = render.weights_of(one, samples)
    assert float(w[0, 0]) == pytest.approx(1 - np.exp(-1.0)) and float(rem[0]) == pytest.approx(np.exp(-1.0))
