"""CoDyNeRF's loss terms: Eq. 13 shapes the density only where it is asked to (a tracked video: not); before Eq. 13
the mesh's normals can stand in for the predicted ones."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import pytest
import torch

from models.avatars.codynerf.training import LossWeights, ray_terms
from models.avatars.registry import load_avatar
from tests.conftest import CODYNERF_DEMO
from tests.models.avatars.test_pose_corrections import rays_at_head


def rays(seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    R, S = 6, 5
    unit = lambda t: t / t.norm(dim=-1, keepdim=True)
    return SimpleNamespace(sigma=torch.rand(R, S, generator=g), weights=torch.rand(R, S, generator=g) / S,
                           factor=None, point_normal=unit(torch.randn(R, S, 3, generator=g)).requires_grad_(),
                           point_grad_normal=unit(torch.randn(R, S, 3, generator=g)).requires_grad_())


def test_eq13_pulls_the_density_only_where_asked():
    dirs = torch.nn.functional.normalize(torch.randn(6, 3), dim=-1)
    codes = (torch.zeros(1, 4),)
    for shapes_density in (True, False):
        r = rays()
        w = replace(LossWeights(), consistency_shapes_density=shapes_density)
        parts = ray_terms(w, r, torch.rand(6, 3), torch.rand(6, 3), dirs, progress=1.0, codes=codes)
        parts["normal_consistency"].backward()
        assert r.point_normal.grad.abs().sum() > 0  # the normals are pulled either way
        grad = r.point_grad_normal.grad
        assert (grad is not None and grad.abs().sum() > 0) if shapes_density else grad is None


@pytest.mark.gl
def test_mesh_normals_first_renders_what_the_untrained_normals_would_without_their_gradients(gl):
    """Before Eq. 13 a tracked video's `all` avatar reads the mesh's normals (LossWeights.mesh_normals_first). N
    starts as the mesh normal (its last layer zero), so that phase renders exactly what the full path renders
    at the start, and no density gradient is taken: the density network sees no second backward."""
    avatar, _ = load_avatar(CODYNERF_DEMO)
    assert avatar.field_cfg.needs_normals
    last = avatar.field.normals.net[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()
    rays, geo = rays_at_head(avatar, gl, 48)
    g = lambda: torch.Generator().manual_seed(5)
    full = avatar.render_rays(rays, geo, 0, g(), training=True)
    first = avatar.render_rays(rays, geo, 0, g(), training=True, mesh_normals=True)
    assert full.buffers["opacity"].max() > 0.5  # the rays do reach the head
    torch.testing.assert_close(first.buffers["rgb"], full.buffers["rgb"], atol=1e-5, rtol=0)
    torch.testing.assert_close(first.buffers["normals"], full.buffers["normals"], atol=1e-5, rtol=0)
    # the stand-in normals are the mesh's: the density's gradient differs from them
    assert (full.buffers["grad_normals"] - first.buffers["grad_normals"]).abs().max() > 1e-2
    first.buffers["rgb"].sum().backward()
    assert all(p.grad is None for p in avatar.field.normals.parameters())  # N is not used in that phase
