"""A primitives avatar as a coloured mesh for other tools (Blender, game engines): its density sampled on a grid
over the posed head (each point's density the sum of the primitives whose boxes hold it, trilinear in each; its
colour their colours weighted by density), the iso-surface where 1 cm of matter lets half the light through
(render/marching.py), and vertex colours from the field at the vertices."""

from __future__ import annotations

import math

import numpy as np
import torch

from models.avatars.primitives import march
from models.head.controls import Controls
from render.marching import marching_tetrahedra

HALF_LIGHT_IN_1CM = math.log(2.0) / 0.01
"""The density (per metre) at which 1 cm of matter lets half the light through: the default surface level."""


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


def avatar_mesh(avatar, controls: Controls | None = None, resolution: int = 96, level: float = HALF_LIGHT_IN_1CM
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The avatar posed by `controls` (rest by default) as vertices (V,3) in metres, triangles (F,3) and vertex
    colours (V,3) uint8: its density's iso-surface at `level` on a resolution^3 grid over its primitives' boxes,
    decoded for a camera in front of the face (the view the colours are for), every texel lit."""
    controls = avatar.at_rest(controls or Controls())
    geo = avatar.geometry(controls)
    eye = geo.translation + geo.rotation @ torch.tensor([0.0, 0.0, 1.0])  # 1 m in front of the face
    with torch.no_grad():
        prims, _ = avatar.decode(geo, avatar.codes(None, geo.code_weights), eye, lit=avatar.casts_shadows)
    reach = prims.half_sizes.norm(dim=1, keepdim=True)
    lo = (prims.centres - reach).min(0).values.numpy()
    hi = (prims.centres + reach).max(0).values.numpy()
    spacing = float((hi - lo).max()) / (resolution - 1)
    axes = [lo[i] + spacing * np.arange(int(np.ceil((hi[i] - lo[i]) / spacing)) + 2) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    density, _ = field_at(prims, torch.as_tensor(grid.reshape(-1, 3), dtype=prims.centres.dtype))
    values = density.numpy().reshape(grid.shape[:3])
    verts, tris = marching_tetrahedra(values, level, lo, spacing)
    if len(verts) == 0:
        raise ValueError(f"no surface: the density nowhere reaches {level:g} per metre")
    _, rgb = field_at(prims, torch.as_tensor(verts, dtype=prims.centres.dtype))
    # a vertex sits where the density is at the level: its colour is the colour of the matter there
    return verts, tris, (rgb.clamp(0, 1).numpy() * 255).round().astype(np.uint8)
