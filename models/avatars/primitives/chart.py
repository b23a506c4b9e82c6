"""The primitives' chart at texel resolution: S x S texels (S = K M, one per voxel column of the decoder's slab
image), each where the chart's ray from the head's centre leaves the template (layout.py's rule for the primitives'
own places), carried by the mesh as it moves. The decoder's geometry maps (the person-specific avatar's expression
maps, the prior's identity and expression maps) are images in this chart, so they line up with its slabs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from models.avatars.primitives.layout import chart_directions, outermost_hits
from models.head.model import HeadModel

GAZE_JOINTS = ("eye_l", "eye_r")
GEOMETRY_SCALE_M = 0.1
"""Geometry maps are in units of this many metres about the head's centre."""


@dataclass(frozen=True)
class ChartSampler:
    """Where each of the chart's S x S texels lies on the template: its triangle (-1: the ray misses the head) and
    barycentric point, rows top (crown) first."""

    size: int
    triangles: np.ndarray  # (S*S,)
    bary: np.ndarray  # (S*S,3)
    centre: np.ndarray  # (3,) the template's centre, the maps' origin

    @property
    def valid(self) -> np.ndarray:
        return self.triangles >= 0


_SAMPLERS: dict[tuple, ChartSampler] = {}


def chart_sampler(model: HeadModel, size: int, front: float = 0.0) -> ChartSampler:
    """The chart at S = size for a head model, its columns crowded to the face by `front` (layout.chart_azimuths;
    computed once per surface, size and front: a ray per texel; the arrays are shared, read them only)."""
    key = (model.surface_key, size, front)
    if key not in _SAMPLERS:
        verts = np.asarray(model.template, np.float64)
        tris = np.asarray(model.triangles, np.int64)
        centre = 0.5 * (verts.min(0) + verts.max(0))
        f, b, _ = outermost_hits(centre, chart_directions(size, front), verts[tris], chunk=64)
        _SAMPLERS[key] = ChartSampler(size, f, b.astype(np.float32), centre.astype(np.float32))
    return _SAMPLERS[key]


def texel_points(sampler: ChartSampler, triangles: torch.Tensor, vertices: torch.Tensor) -> torch.Tensor:
    """(S*S,3) each texel's point on a mesh (V,3) with the template's triangles (F,3); the centre where invalid."""
    f = torch.as_tensor(np.maximum(sampler.triangles, 0), device=vertices.device)
    b = torch.as_tensor(sampler.bary, device=vertices.device, dtype=vertices.dtype)
    points = (vertices[triangles[f]] * b[:, :, None]).sum(1)
    centre = torch.as_tensor(sampler.centre, device=vertices.device, dtype=vertices.dtype)
    return torch.where(torch.as_tensor(sampler.valid, device=vertices.device)[:, None], points, centre)


def geometry_map(sampler: ChartSampler, triangles: torch.Tensor, head_vertices: torch.Tensor) -> torch.Tensor:
    """(3,S,S) the texels' points of a mesh given in the head's frame (unposed by the head's rigid pose), about the
    template's centre in GEOMETRY_SCALE_M units; 0 off the head."""
    S = sampler.size
    p = texel_points(sampler, triangles, head_vertices)
    p = (p - torch.as_tensor(sampler.centre, device=p.device, dtype=p.dtype)) / GEOMETRY_SCALE_M
    return p.T.reshape(3, S, S)


def carried_by(model: HeadModel, names: tuple[str, ...]) -> np.ndarray:
    """(V,) the vertices that the joints of these names carry (skin weight over 0.5); names the model lacks carry
    none."""
    carried = np.zeros(model.num_vertices, bool)
    for name in names:
        if name in model.joint_names:
            carried |= model.weights[:, model.joint_names.index(name)] > 0.5
    return carried


def eye_cells(model: HeadModel, size: int, cells: int = 8, front: float = 0.0) -> torch.Tensor:
    """(1,1,cells,cells): 1 on the chart's cells whose texels lie on an eyeball (and their neighbours), where the
    seed lets gaze act; ones everywhere for a head without eye joints."""
    if not any(j in model.joint_names for j in GAZE_JOINTS):
        return torch.ones(1, 1, cells, cells)
    on_eye = carried_by(model, GAZE_JOINTS)
    s = chart_sampler(model, size, front)
    texel = np.zeros(size * size, np.float32)
    ok = s.valid
    texel[ok] = on_eye[np.asarray(model.triangles)[s.triangles[ok]]].any(1)
    grid = F.adaptive_max_pool2d(torch.as_tensor(texel).reshape(1, 1, size, size), cells)
    return F.max_pool2d(grid, 3, stride=1, padding=1)


EXPRESSION_REACH_M = 3e-3
"""A vertex is on the moving face where some expression weight of 1 moves it further than this (expression_share):
on ICT's head 40% of the vertices (at 1 mm 65%, and every 8 x 8 cell of the front-2 chart touches one)."""


def face_vertices(model: HeadModel) -> np.ndarray:
    """(V,) the vertices on the part of the head the controls move: some expression weight of 1 moves it further
    than EXPRESSION_REACH_M, or the jaw or an eye carries it (the face; not the crown, the back, the neck's sides)."""
    moved = np.abs(np.asarray(model.expr_basis)).max(axis=(1, 2)) > EXPRESSION_REACH_M \
        if model.expr_basis.shape[-1] else np.zeros(model.num_vertices, bool)
    return moved | carried_by(model, (*GAZE_JOINTS, "jaw"))


def expression_share(model: HeadModel, size: int, cells: int, front: float = 0.0) -> torch.Tensor:
    """(1,1,cells,cells): the share of each chart cell's texels that lie on the part of the head the controls move
    (face_vertices' triangles); 0 on the crown, the back and the sides of the neck."""
    moved = face_vertices(model)
    s = chart_sampler(model, size, front)
    texel = np.zeros(size * size, np.float32)
    texel[s.valid] = moved[np.asarray(model.triangles)[s.triangles[s.valid]]].all(1)
    return F.adaptive_avg_pool2d(torch.as_tensor(texel).reshape(1, 1, size, size), cells)
