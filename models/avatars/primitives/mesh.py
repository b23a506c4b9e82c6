"""A primitives avatar's field for mesh export (models/avatars/mesh.py): each point's density the sum of the
primitives whose boxes hold it, trilinear in each; its colour their colours weighted by density."""

from __future__ import annotations

import torch

from models.avatars.mesh import MeshField, front_eye
from models.avatars.primitives import march
from models.head.controls import Controls


@torch.no_grad()
def field_at(prims: march.Primitives, points: torch.Tensor, chunk: int = 8192) -> tuple[torch.Tensor, torch.Tensor]:
    """density (N,) and colour (N,3) of the primitives at world points (N,3): densities summed over the boxes
    that hold a point, colours weighted by them (0 density: black)."""
    values = torch.cat([prims.density[..., None], prims.colour[..., :3]], -1)
    density = torch.zeros(len(points), dtype=values.dtype)
    colour = torch.zeros(len(points), 3, dtype=values.dtype)
    for a in range(0, len(points), chunk):
        p = points[a:a + chunk]
        local = torch.einsum("pji,npj->npi", prims.rotations, p[:, None] - prims.centres[None]) \
            / prims.half_sizes[None].clamp_min(1e-12)
        n, k = torch.nonzero((local.abs() <= 1.0).all(-1), as_tuple=True)
        if len(n) == 0:
            continue
        got = march.trilinear(values, k, local[n, k])  # (hits, 4)
        d = got[:, 0].clamp_min(0.0)
        density[a:a + chunk].index_add_(0, n, d)
        colour[a:a + chunk].index_add_(0, n, got[:, 1:] * d[:, None])
    return density, colour / density.clamp_min(1e-12)[:, None]


@torch.no_grad()
def primitives_mesh_field(avatar, controls: Controls) -> MeshField:
    """The frame decoded once, for a camera in front of the face (the view the colours are for), every texel lit;
    the box round every primitive's box."""
    geo = avatar.geometry(controls)
    eye = front_eye(geo.rotation, geo.translation)
    prims, _ = avatar.decode(geo, avatar.codes(None, geo.code_weights), eye, lit=avatar.casts_shadows)
    reach = prims.half_sizes.norm(dim=1, keepdim=True)
    return MeshField((prims.centres - reach).min(0).values.numpy(), (prims.centres + reach).max(0).values.numpy(),
                     lambda p: field_at(prims, p.to(prims.centres.dtype))[0],
                     lambda p: field_at(prims, p.to(prims.centres.dtype))[1])
