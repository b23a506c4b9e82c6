"""Where the volumetric primitives sit on the guide mesh (MVP, Lombardi et al. 2021; Cao et al. 2022, Section 3.1): one
primitive per cell of a K x K grid over a 2D layout of the head's surface, at the surface point of the cell's
centre, turned to the surface (tangent, bitangent, normal) and sized to the cell. The decoder writes its slabs in
the same grid, so neighbouring primitives are neighbouring pixels of its convolutions.

The layout is a spherical chart of the template's outer surface about the head's centre (azimuth along the grid's
columns, elevation along its rows), the same for every head model: the models' own UVs do not give one square
layout (ICT's are split over seven UDIM tiles, u from 0 to 7; FLAME files often come without them). Each cell's
primitive sits where the ray from the centre through the cell's direction leaves the mesh (the outermost hit), so
the skin, the eyes' fronts and the lips get primitives and nothing hidden inside does."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from models.head.model import HeadModel

ELEVATION_DEG = (-60.0, 80.0)
"""The chart's rows, from below the chin (the neck) to the crown."""


@dataclass(frozen=True)
class PrimitiveLayout:
    """P primitives on a K x K grid: the template triangle each sits on, its barycentric point, its grid cell and
    its half-size on the template (metres)."""

    grid: int  # K
    triangles: np.ndarray  # (P,) int
    bary: np.ndarray  # (P,3)
    cells: np.ndarray  # (P,2) int: row, column of the K x K grid
    half_size_m: np.ndarray  # (P,)

    @property
    def count(self) -> int:
        return len(self.triangles)


def outermost_hits(origin: np.ndarray, dirs: np.ndarray, tri: np.ndarray, chunk: int = 16, cull: bool = True
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For rays from `origin` along dirs (N,3) (unit) against triangles tri (F,3,3): the farthest hit's triangle
    (N,) (-1 where none), barycentrics (N,3) and distance (N,) (0 where none; Moller-Trumbore with the inside
    test).

    cull: rays go in tiles of nearby directions, each tested only against the triangles that may meet one of them:
    a triangle's directions from the origin lie in the cap about their mean that holds its corners (caps under a
    right angle are convex), so one whose cap is farther from a tile's cap than their two radii is met by none of
    the tile's rays. The same hits as testing every triangle (a test holds them equal), at a fraction of the work:
    the chart of ICT's 34k triangles at 128 x 128 texels took 27 s untiled.

    >>> tri = np.array([[[-1, -1, 2], [1, -1, 2], [0, 1, 2]], [[-1, -1, 3], [1, -1, 3], [0, 1, 3]]], float)
    >>> f, b, t = outermost_hits(np.zeros(3), np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), tri)
    >>> f.tolist(), t.tolist(), b[0].round(3).tolist()  # the plane z = 3 is the farther; (0, 0) = v0/4 + v1/4 + v2/2
    ([1, -1], [3.0, 0.0], [0.25, 0.25, 0.5])
    """
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    s = origin - tri[:, 0]
    q = np.cross(s, e1)  # (F,3), the same for every ray (one origin)
    qe2 = np.einsum("fk,fk->f", e2, q)
    best_f = np.full(len(dirs), -1)
    best_b = np.zeros((len(dirs), 3))
    best_t = np.zeros(len(dirs))
    tiles = direction_tiles(dirs) if cull else [np.arange(a, min(a + chunk, len(dirs)))
                                                 for a in range(0, len(dirs), chunk)]
    centre, radius = direction_caps(tri - origin) if cull else (None, None)
    for rows_of in tiles:
        d = dirs[rows_of]  # (C,3)
        cand = np.arange(len(tri))
        if cull:
            mid, spread = direction_caps(d[None])
            apart = np.arccos(np.clip(centre @ mid[0], -1.0, 1.0))
            cand = np.nonzero(apart <= radius + spread[0] + 1e-6)[0]
            if len(cand) == 0:
                continue
        p = np.cross(d[:, None], e2[cand][None])  # (C,F',3)
        det = np.einsum("fk,cfk->cf", e1[cand], p)
        ok = np.abs(det) > 1e-18
        det = np.where(ok, det, 1.0)
        u = np.einsum("fk,cfk->cf", s[cand], p) / det
        v = np.einsum("ck,fk->cf", d, q[cand]) / det
        t = qe2[cand][None] / det
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        t_hit = np.where(hit, t, -np.inf)
        f = t_hit.argmax(1)
        any_hit = hit.any(1)
        rows = np.arange(len(d))
        best_f[rows_of] = np.where(any_hit, cand[f], -1)
        best_t[rows_of] = np.where(any_hit, t_hit[rows, f], 0.0)
        best_b[rows_of] = np.where(any_hit[:, None], np.stack([1 - u[rows, f] - v[rows, f], u[rows, f], v[rows, f]], 1),
                                   0.0)
    return best_f, best_b, best_t


def direction_caps(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For sets of points (F,n,3) seen from the origin: the unit mean direction (F,3) of each set and the angle
    (F,) (radians) from it to the farthest of its points; pi (every direction) where a point lies at the origin or
    the cap reaches a right angle (larger caps are not convex: the set's hull may leave them)."""
    length = np.linalg.norm(points, axis=-1, keepdims=True)
    unit = points / np.maximum(length, 1e-300)
    mean = unit.sum(1)
    mean /= np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-300)
    cos = np.einsum("fnk,fk->fn", unit, mean).min(1)
    radius = np.arccos(np.clip(cos, -1.0, 1.0))
    return mean, np.where((length[..., 0].min(1) > 0) & (cos > 1e-6), radius, np.pi)


def direction_tiles(dirs: np.ndarray, tile_deg: float = 6.0) -> list[np.ndarray]:
    """The rows of dirs (N,3) (unit, +y up) grouped by tile_deg x tile_deg cells of elevation and azimuth."""
    el = np.degrees(np.arcsin(np.clip(dirs[:, 1], -1.0, 1.0)))
    az = np.degrees(np.arctan2(dirs[:, 0], dirs[:, 2]))
    key = np.floor((el + 90.0) / tile_deg) * 1000 + np.floor((az + 180.0) / tile_deg)
    order = np.argsort(key, kind="stable")
    return np.split(order, np.nonzero(np.diff(key[order]))[0] + 1)


def chart_azimuths(grid: int, front: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The chart's columns: each one's azimuth at its centre and its width (K,) (radians). front = a > 0 crowds
    them to the face: azimuth = pi w(s), w(s) = sinh(a s) / sinh(a), over s = 2u - 1 of the place u in [0, 1]
    along the columns (a column's width: between its edges' azimuths); 0: even columns (w(s) = s).

    >>> az, width = chart_azimuths(8, 2.0)  # face: pi sinh(0.5) / sinh(2); back: pi (1 - sinh(1.5) / sinh(2))
    >>> np.degrees(width[3:5]).round(2).tolist(), np.degrees(width[[0, 7]]).round(2).tolist()
    ([25.86, 25.86], [74.32, 74.32])
    >>> round(float(np.degrees(width).sum()), 9), np.degrees(chart_azimuths(8)[1]).tolist()  # a turn; even
    (360.0, [45.0, 45.0, 45.0, 45.0, 45.0, 45.0, 45.0, 45.0])
    """
    if front <= 0:  # as the avatars before `front` had them, to the last bit
        u = (np.arange(grid) + 0.5) / grid
        return np.radians(np.interp(u, [0, 1], (-180.0, 180.0))), np.full(grid, np.radians(360.0) / grid)
    w = lambda s: np.sinh(front * s) / np.sinh(front)
    edges = np.pi * w(np.linspace(-1.0, 1.0, grid + 1))
    return np.pi * w(2.0 * (np.arange(grid) + 0.5) / grid - 1.0), np.diff(edges)


def chart_directions(grid: int, front: float = 0.0) -> np.ndarray:
    """(K*K,3) unit directions through the cell centres of the chart, row-major (row = elevation, column =
    azimuth: chart_azimuths), +y up, +z the face's front."""
    el = np.radians(np.interp((np.arange(grid) + 0.5) / grid, [0, 1], ELEVATION_DEG))[::-1]  # row 0: the crown
    az = chart_azimuths(grid, front)[0]
    e, a = np.meshgrid(el, az, indexing="ij")
    return np.stack([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)], -1).reshape(-1, 3)


MIN_INCIDENCE = 0.4
"""The least cosine between a chart ray and the surface it leaves through that sizes a primitive: a ray that leaves
at a grazing angle (the neck, below the chin) covers a patch 1/cos as long as the cell is wide, up to 2.5x."""


_LAYOUTS: dict[tuple, PrimitiveLayout] = {}


def primitive_layout(model: HeadModel, grid: int, overlap: float = 1.3, front: float = 0.0) -> PrimitiveLayout:
    """A primitive at each cell of the chart whose ray leaves the template somewhere; its half-size is half the
    surface patch the cell covers (the distance times the cell's angle, the larger of its two sides, over the
    cosine at which the ray leaves the surface, at least MIN_INCIDENCE), times `overlap` so that neighbours leave
    no gaps. front: the columns crowded to the face (chart_azimuths). Computed once per surface
    (HeadModel.surface_key) and arguments, 0.1-0.8 s a time here (a ray per cell): the arrays are shared, read them,
    copy before writing."""
    key = (model.surface_key, grid, overlap, front)
    if key not in _LAYOUTS:
        _LAYOUTS[key] = layout_of(model, grid, overlap, front)
    return _LAYOUTS[key]


def layout_of(model: HeadModel, grid: int, overlap: float, front: float) -> PrimitiveLayout:
    """primitive_layout's arrays, computed."""
    verts = np.asarray(model.template, np.float64)
    tris = np.asarray(model.triangles, np.int64)
    centre = 0.5 * (verts.min(0) + verts.max(0))
    directions = chart_directions(grid, front)
    f, b, t = outermost_hits(centre, directions, verts[tris])
    keep = np.nonzero(f >= 0)[0]
    if len(keep) == 0:
        raise ValueError(f"head model '{model.name}': no ray from its centre leaves its surface")
    el = np.radians(np.interp((keep // grid + 0.5) / grid, [0, 1], ELEVATION_DEG))
    d_az = chart_azimuths(grid, front)[1][keep % grid] * np.cos(el)
    d_el = np.radians(np.ptp(ELEVATION_DEG)) / grid
    tri = verts[tris[f[keep]]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-18)
    incidence = np.abs((normal * directions[keep]).sum(1)).clip(MIN_INCIDENCE, 1.0)
    half = 0.5 * overlap * t[keep] * np.maximum(d_az, d_el) / incidence
    return PrimitiveLayout(grid, f[keep], b[keep], np.stack([keep // grid, keep % grid], 1),
                           half.astype(np.float32))


def surface_frames(vertices: torch.Tensor, triangles: torch.Tensor, layout_tris: torch.Tensor,
                   bary: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The primitives' places on a posed mesh (V,3): centres (P,3) and rotations (P,3,3) whose columns are the
    triangle's first edge (tangent), the normal cross it (bitangent) and the normal."""
    tri = vertices[triangles[layout_tris]]  # (P,3,3)
    centre = (bary[:, :, None] * tri).sum(1)
    e1 = tri[:, 1] - tri[:, 0]
    n = torch.linalg.cross(e1, tri[:, 2] - tri[:, 0])
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    t = e1 / e1.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    b = torch.linalg.cross(n, t)
    return centre, torch.stack([t, b, n], -1)
