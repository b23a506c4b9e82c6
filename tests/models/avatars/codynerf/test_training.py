"""CoDyNeRF's loss terms: Eq. 13 shapes the density only where it is asked to (a tracked video: not)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import torch

from models.avatars.codynerf.training import LossWeights, ray_terms


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
