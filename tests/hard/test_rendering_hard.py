"""Hard cases for rendering, swept by hypothesis: the sampler (rays that miss, graze or start inside
the head's box, surfaces at 0 or far away), compositing (densities up to 1e6, zero-length intervals), the
fields (points metres and kilometres from the mesh, zero density gradients) and a whole CoDyNeRF and NerFACE
ray batch: every output finite, and every gradient training takes finite too."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from models.avatars.codynerf.avatar import CoDyNeRFAvatar
from models.avatars.codynerf.field import CoDyNeRFField, FieldConfig
from models.avatars.codynerf.prior import PriorSamples
from models.avatars.effects import EFFECTS
from models.avatars.nerface.avatar import NerfaceAvatar, NerfaceConfig
from models.head.controls import Controls
from render.rays import Rays
from render.sampling import fine_samples, shell_or_box_samples
from render.shadow_map import LightDepthMap
from render.volume import composite, weights_from_density

SWEEP = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
coord = st.floats(-1e3, 1e3, allow_nan=False, width=32)
unit = st.tuples(coord, coord, coord).filter(lambda v: np.linalg.norm(v) > 1e-3).map(
    lambda v: np.asarray(v, np.float32) / np.linalg.norm(v))
axis = st.sampled_from([np.array(v, np.float32) for v in np.eye(3)] + [-np.eye(3, dtype=np.float32)[0]])
surface = st.sampled_from([float("inf"), 0.0, 1e-6, 0.3, 1e4])


def rays_of(origins, directions, surfaces) -> Rays:
    return Rays(torch.as_tensor(np.stack(origins), dtype=torch.float32),
                torch.as_tensor(np.stack(directions), dtype=torch.float32),
                torch.as_tensor(surfaces, dtype=torch.float32))


inside = st.floats(-0.0625, 0.0625, allow_nan=False, width=32)  # within the head: a camera inside it
origin = st.one_of(st.tuples(coord, coord, coord), st.tuples(inside, inside, inside)).map(
    lambda v: np.asarray(v, np.float32))
ray_batch = st.integers(1, 6).flatmap(lambda n: st.tuples(
    st.lists(origin, min_size=n, max_size=n),
    st.lists(st.one_of(unit, axis), min_size=n, max_size=n),
    st.lists(surface, min_size=n, max_size=n)))


@SWEEP
@given(ray_batch, st.integers(2, 16), st.booleans())
def test_sampler_intervals_are_finite_sorted_and_inside_the_box(batch, n, jitter):
    rays = rays_of(*batch)
    box_min, box_max = torch.tensor([-0.1, -0.15, -0.1]), torch.tensor([0.1, 0.15, 0.12])
    g = torch.Generator().manual_seed(0) if jitter else None
    s = shell_or_box_samples(rays.origins, rays.directions, rays.surface_t, box_min, box_max, n, 0.03, g)
    assert torch.isfinite(s.t_starts).all() and torch.isfinite(s.t_ends).all()
    assert (s.deltas >= 0).all() and (s.t_starts[:, 1:] >= s.t_starts[:, :-1] - 1e-6).all()
    assert (s.t_starts[s.valid] >= 0).all()
    # A second pass drawn from weights that are all zero, or one huge spike, stays finite and sorted.
    for weights in (torch.zeros_like(s.t_mid), torch.zeros_like(s.t_mid).index_fill(1, torch.tensor([0]), 1e30)):
        f = fine_samples(s, weights, 4, g)
        assert torch.isfinite(f.t_starts).all() and (f.deltas >= -1e-6).all()


@SWEEP
@given(st.lists(st.sampled_from([0.0, 1e-12, 1.0, 100.0, 1e6]), min_size=4, max_size=4),
       st.lists(st.sampled_from([0.0, 1e-9, 5e-3, 1.0]), min_size=4, max_size=4))
def test_compositing_huge_densities_and_empty_intervals(sigmas, deltas):
    sigma = torch.tensor([sigmas], dtype=torch.float64, requires_grad=True)
    delta = torch.tensor([deltas], dtype=torch.float64)
    rgb = torch.rand(1, 4, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(1), requires_grad=True)
    weights, remaining = weights_from_density(sigma, delta)
    out = composite(weights, rgb, remaining, torch.ones(3, dtype=torch.float64))
    assert torch.isfinite(out).all() and (weights >= 0).all()
    assert float((weights.sum() + remaining.sum()).detach()) == pytest.approx(1.0, abs=1e-9)  # light conserved
    gs, gc = torch.autograd.grad(out.sum(), (sigma, rgb))
    assert torch.isfinite(gs).all() and torch.isfinite(gc).all()


def field_inputs(n: int, distance: float, scale: float, seed: int):
    g = torch.Generator().manual_seed(seed)
    x = (torch.randn(n, 3, generator=g) * scale).requires_grad_(True)
    normal = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
    offset = torch.randn(n, 3, generator=g) * 0.01
    prior = PriorSamples(torch.zeros(n, dtype=torch.long), torch.full((n,), distance), offset, offset / 2,
                         offset / 2, normal)
    return x, prior


@functools.cache
def lit_field(seed: int) -> CoDyNeRFField:
    """Every effect, with a shadow factor; random weights (one field per seed)."""
    torch.manual_seed(seed)
    return CoDyNeRFField(FieldConfig(effects=EFFECTS, light_dir=(0.0, 1.0, 0.0)), 68)


@settings(max_examples=20, deadline=None)
@given(st.sampled_from([0.0, 0.03, 10.0, 1e6]), st.sampled_from([1e-3, 0.1, 10.0, 1e3, 1e6]),
       st.integers(0, 3))
def test_fields_finite_far_from_the_mesh_with_finite_gradients(distance, scale, seed):
    field = lit_field(seed)
    cfg = field.cfg
    x, prior = field_inputs(8, distance, scale, seed)
    out = field.geometry(x, prior, torch.zeros(1, cfg.deform_code_dim), create_graph=True)
    view = torch.nn.functional.normalize(torch.randn(8, 3), dim=-1)
    rgb = field.appearance(out, prior, view, torch.zeros(1, cfg.appearance_code_dim), torch.zeros(1, 3 * 68),
                           torch.rand(8))
    for t in (out.sigma, out.normal, out.grad_normal, rgb):
        assert torch.isfinite(t).all()
    loss = rgb.sum() + out.sigma.sum() + (out.normal * out.grad_normal).sum()  # what training differentiates
    grads = torch.autograd.grad(loss, [p for p in field.parameters() if p.requires_grad], allow_unused=True)
    assert all(g is None or torch.isfinite(g).all() for g in grads)


@settings(max_examples=12, deadline=None)
@given(st.sampled_from([0.0, 0.1, 10.0, 1e3, 1e6]), st.integers(0, 2))
def test_nerface_field_finite_far_away_with_finite_gradients(distance, seed):
    """The NerFACE baseline's MLP at points metres (up to 1e6 m) from the head, with huge conditions."""
    from models.avatars.nerface.avatar import NerfaceConfig, NerfaceMLP

    torch.manual_seed(seed)
    cfg = NerfaceConfig(width=32, depth=4)
    net = NerfaceMLP(cfg, condition_dim=20)
    x = torch.nn.functional.normalize(torch.randn(8, 3), dim=-1) * distance
    view = torch.nn.functional.normalize(torch.randn(8, 3), dim=-1)
    condition = torch.randn(8, 20) * 1e3
    sigma, rgb = net(x, view, condition, 0.15)
    assert torch.isfinite(sigma).all() and torch.isfinite(rgb).all()
    grads = torch.autograd.grad(sigma.sum() + rgb.sum(), list(net.parameters()), allow_unused=True)
    assert all(g is None or torch.isfinite(g).all() for g in grads)


def test_zero_density_gradient_gives_zero_normals_not_nan():
    cfg = FieldConfig(effects=("shading",))
    field = CoDyNeRFField(cfg, 1)
    for p in field.density.parameters():
        torch.nn.init.zeros_(p)  # a constant density: its gradient is exactly zero everywhere
    x, prior = field_inputs(4, 0.0, 0.1, 0)
    out = field.geometry(x, prior, torch.zeros(1, cfg.deform_code_dim), create_graph=True)
    assert torch.equal(out.grad_normal, torch.zeros_like(out.grad_normal))
    (g,) = torch.autograd.grad(out.normal.sum(), x)
    assert torch.isfinite(out.normal).all() and torch.isfinite(g).all()


@pytest.fixture(scope="module")
def avatars(builtin_model):
    """A CoDyNeRF avatar with every effect and a shadow factor, and a small NerFACE, untrained (random fields)."""
    torch.manual_seed(0)
    cody = CoDyNeRFAvatar.for_capture(builtin_model, 2, np.ones(3, np.float32), EFFECTS,
                                      {"key_light": {"direction": [0.3, 0.8, 0.5]}})
    nerface = NerfaceAvatar(builtin_model, NerfaceConfig(width=32, depth=2, coarse_samples=8, fine_samples=8), 2,
                            np.ones(3, np.float32))
    return cody, nerface


def light_map(depth: float) -> LightDepthMap:
    """A shadow map without GL: an orthographic light above the head, every texel at `depth`."""
    view = torch.eye(4)
    view[:3, :3] = torch.tensor([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # looking down -y
    view[2, 3] = -1.0
    return LightDepthMap(view, torch.diag(torch.tensor([4.0, 4.0, -1.0, 1.0])), torch.full((16, 16), depth))


POSES = (Controls(), Controls(root=np.array([0.0, np.pi, 0.0], np.float32)),
         Controls(root=np.array([np.pi - 1e-6, 0.0, 0.0], np.float32), jaw=np.array([1.5, 0, 0], np.float32)),
         Controls(expression=np.full(16, 10.0, np.float32)))
"""Neutral, turned right round, rolled by nearly pi with the jaw wide open, expressions ten times their range."""


@pytest.fixture(scope="module")
def geometries(avatars):
    cody, nerface = avatars
    return [(cody.geometry(c), nerface.geometry(c)) for c in POSES]


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ray_batch, st.integers(0, len(POSES) - 1), st.sampled_from([0.5, float("inf")]))
def test_whole_ray_batches_finite_with_finite_gradients(avatars, geometries, batch, pose, light_depth):
    cody, nerface = avatars
    rays = rays_of(*batch)
    geo = dataclasses.replace(geometries[pose][0], light=light_map(light_depth))
    for training in (True, False):
        out = cody.render_rays(rays, geo, 1, torch.Generator().manual_seed(0), training=training)
        for k, v in out.buffers.items():
            assert not torch.isnan(v).any() and torch.isfinite(v).all(), k
    out = cody.render_rays(rays, geo, 1, torch.Generator().manual_seed(0), training=True, create_graph=True)
    grads = torch.autograd.grad(out.buffers["rgb"].sum() + out.internals.sigma.sum(),
                                [p for p in cody.parameters() if p.requires_grad], allow_unused=True)
    assert all(g is None or torch.isfinite(g).all() for g in grads)
    out = nerface.render_rays(rays, geometries[pose][1], 1, torch.Generator().manual_seed(0), training=True)
    assert all(torch.isfinite(v).all() for v in out.buffers.values())
    grads = torch.autograd.grad(out.buffers["rgb"].sum(), list(nerface.parameters()), allow_unused=True)
    assert all(g is None or torch.isfinite(g).all() for g in grads)
