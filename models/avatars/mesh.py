"""An avatar as a coloured mesh for other tools (Blender, game engines): the avatar's density sampled on a grid over
its posed head, the iso-surface where 1 cm of matter lets half the light through (or, in a softer field, at half
its highest density; render/marching.py), and vertex
colours from its appearance at the vertices, seen from in front of the face with every effect the avatar has.

Each model says what its field is (Avatar.mesh_field): primitives sum their voxel grids (primitives/mesh.py),
CoDyNeRF evaluates its deformation, density and appearance networks (codynerf/avatar.py)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from models.head.controls import Controls
from render.marching import iso_surface

HALF_LIGHT_IN_1CM = math.log(2.0) / 0.01
"""The density (per metre) at which 1 cm of matter lets half the light through: the default surface level."""


@dataclass
class MeshField:
    """A posed avatar's density and colour at world points, and the box that holds all of its matter."""

    lo: np.ndarray  # (3,) metres
    hi: np.ndarray
    density: Callable[[torch.Tensor], torch.Tensor]
    """(N,3) world points -> (N,) density, per metre."""
    colour: Callable[[torch.Tensor], torch.Tensor]
    """(N,3) world points -> (N,3) colour in [0,1], as seen from in front of the face."""


def in_chunks(fn: Callable[[torch.Tensor], torch.Tensor], points: torch.Tensor, chunk: int = 65536
              ) -> torch.Tensor:
    with torch.no_grad():
        return torch.cat([fn(points[a:a + chunk]) for a in range(0, len(points), chunk)])


def front_eye(rotation: torch.Tensor, centre: torch.Tensor) -> torch.Tensor:
    """A point 1 m in front of the face (the head's +z): the camera the exported colours are seen from."""
    return centre + rotation @ torch.tensor([0.0, 0.0, 1.0], dtype=centre.dtype, device=centre.device)


def surface_level(values: np.ndarray) -> float:
    """Where 1 cm of matter lets half the light through; in a softer field, which nowhere gets that dense (a short
    CoDyNeRF training: tens per metre over a few centimetres), half its highest density.

    >>> surface_level(np.array([0.0, 500.0])) == HALF_LIGHT_IN_1CM, surface_level(np.array([0.0, 40.0]))
    (True, 20.0)
    """
    return float(min(HALF_LIGHT_IN_1CM, 0.5 * float(values.max())))


def avatar_mesh(avatar, controls: Controls | None = None, resolution: int = 96, level: float | None = None,
                rasterizer=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The avatar posed by `controls` (rest by default) as vertices (V,3) in metres, triangles (F,3), vertex
    colours (V,3) uint8 and the level used: its density's iso-surface at `level` (default: surface_level) on a
    grid of `resolution` points along the longest side of its field's box. ValueError where there is no surface
    (or the model has no field to export)."""
    field = avatar.mesh_field(avatar.card.at_rest(controls or Controls()), rasterizer)
    lo, hi = np.asarray(field.lo, np.float64), np.asarray(field.hi, np.float64)
    spacing = float((hi - lo).max()) / (resolution - 1)
    axes = [lo[i] + spacing * np.arange(int(np.ceil((hi[i] - lo[i]) / spacing)) + 2) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    density = in_chunks(field.density, torch.as_tensor(grid.reshape(-1, 3), dtype=torch.float32))
    values = density.cpu().numpy().reshape(grid.shape[:3])
    level = surface_level(values) if level is None else level
    verts, tris = iso_surface(values, level, lo, spacing)
    if len(verts) == 0:
        raise ValueError(f"no surface: the density nowhere reaches {level:g} per metre")
    rgb = in_chunks(field.colour, torch.as_tensor(verts, dtype=torch.float32))
    # a vertex sits where the density is at the level: its colour is the colour of the matter there
    return verts, tris, (rgb.clamp(0, 1).cpu().numpy() * 255).round().astype(np.uint8), level
