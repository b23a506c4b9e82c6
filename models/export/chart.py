"""The texture chart of an exported head: where each triangle lies on the texture.

A glTF vertex carries one texture coordinate, so a head-model vertex on a seam of the chart (where the texture's
edge cuts the surface) becomes two or more glTF vertices. The first V glTF vertices are the head model's, in its
order; the seam copies follow, each naming the vertex it copies (`vertex_of`).

Coordinates are glTF's: u right, v down from the image's top-left corner, the whole texture in [0,1]. A head model's
own UVs (ICT's, the built-in head's) are OBJ's, v up, and may spread over UDIM tiles (ICT's triangles lie on two):
they are turned over and the tiles laid out on a grid over one texture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models.head.model import HeadModel


@dataclass(frozen=True, eq=False)
class Chart:
    """A head model's triangles on a texture, its vertices split along the chart's seams."""

    vertex_of: np.ndarray  # (N,) int64: the head-model vertex each glTF vertex copies; vertex_of[:V] = 0..V-1
    uv: np.ndarray  # (N,2) float32: texture coordinates, glTF's (v down), in [0,1]
    triangles: np.ndarray  # (F,3) int32: the head model's triangles, in its order, on the N vertices
    source: str  # where the chart came from: "head model" or "xatlas"

    @property
    def seam_copies(self) -> int:
        return len(self.vertex_of) - int(self.vertex_of.max(initial=-1)) - 1


def split_seams(triangles: np.ndarray, corner_uv: np.ndarray, n_vertices: int, source: str) -> Chart:
    """A Chart from each triangle corner's texture coordinate: one glTF vertex per distinct (vertex, uv) pair.

    triangles: (F,3) head-model vertex ids; corner_uv: (F,3,2). A vertex's first pair (lowest u, then v) keeps its
    own index; the others are appended in vertex order. A vertex on no triangle keeps uv (0, 0).

    >>> tris = np.array([[0, 1, 2], [0, 2, 3]])
    >>> uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0.5, 0], [1, 1], [0, 1]]], np.float32)  # vertex 0 on a seam
    >>> c = split_seams(tris, uv, 5, "test")
    >>> c.vertex_of.tolist(), c.triangles.tolist(), c.uv[5].tolist()
    ([0, 1, 2, 3, 4, 0], [[0, 1, 2], [5, 2, 3]], [0.5, 0.0])
    """
    tris = np.asarray(triangles, np.int64)
    assert corner_uv.shape == (*tris.shape, 2), f"corner_uv must be (F,3,2), got {corner_uv.shape}"
    rows = np.column_stack([tris.ravel(), np.asarray(corner_uv, np.float32).reshape(-1, 2)]).astype(np.float64)
    pairs, inverse = np.unique(rows, axis=0, return_inverse=True)  # sorted by vertex, then u, then v
    vid = pairs[:, 0].astype(np.int64)
    first = np.r_[True, vid[1:] != vid[:-1]]
    index = np.empty(len(pairs), np.int64)
    index[first] = vid[first]
    index[~first] = n_vertices + np.arange(int((~first).sum()))
    vertex_of = np.concatenate([np.arange(n_vertices), vid[~first]])
    uv = np.zeros((len(vertex_of), 2), np.float32)
    uv[index] = pairs[:, 1:]
    return Chart(vertex_of, uv, index[inverse.ravel()].reshape(tris.shape).astype(np.int32), source)


def model_corner_uv(head: HeadModel) -> np.ndarray:
    """(F,3,2) the head model's own UVs at each triangle corner, in glTF's convention on one texture: v turned over
    (OBJ's v is up), and UDIM tiles (the unit squares the triangles' centres fall in) laid out on a grid of
    c = ceil(sqrt(n)) columns and ceil(n / c) rows, in the order of their (u, v) corners (ICT's two tiles side by
    side, each half the texture's width)."""
    uv = np.asarray(head.uv, np.float64)[head.triangles_uv]
    tile = np.floor(uv.mean(1))  # (F,2)
    tiles, which = np.unique(tile, axis=0, return_inverse=True)
    cols = math.ceil(math.sqrt(len(tiles)))
    rows = math.ceil(len(tiles) / cols)
    cell = np.stack([np.arange(len(tiles)) % cols, np.arange(len(tiles)) // cols], 1)[which.ravel()]  # (F,2)
    packed = (uv - tile[:, None] + cell[:, None]) / [cols, rows]
    return np.stack([packed[..., 0], 1.0 - packed[..., 1]], -1).astype(np.float32)


def atlas_corner_uv(vertices: np.ndarray, triangles: np.ndarray, texture_px: int) -> np.ndarray:
    """(F,3,2) an xatlas atlas of the mesh (charts cut where the surface bends, packed on a texture of texture_px
    with 2 texels between charts), each triangle corner's coordinate."""
    import xatlas

    atlas = xatlas.Atlas()
    atlas.add_mesh(np.asarray(vertices, np.float32), np.asarray(triangles, np.uint32))
    pack = xatlas.PackOptions()
    pack.resolution, pack.padding, pack.bilinear = int(texture_px), 2, True
    atlas.generate(pack_options=pack)
    vmapping, indices, uvs = atlas[0]
    if indices.shape != np.shape(triangles) or not np.array_equal(vmapping[indices], triangles):
        raise ValueError("xatlas changed the mesh's triangles (degenerate ones?); cannot chart it")
    return np.asarray(uvs, np.float32)[indices]


MAX_UV_LAYERS = 1.5
"""How many times over a head model's UV triangles may cover the texture they lie on and still serve as its one
texture's chart: an atlas covers it once (rasterized edges make the union a little larger); the built-in head's
layout 1.15; ICT's 2.9 (its mouth and eye sockets and its eyeballs lie on the face's texels), which then gets an
xatlas atlas of its own."""


def uv_layers(corner_uv: np.ndarray, grid_px: int = 1024) -> float:
    """The triangles' summed UV area over the area of their union (rasterized on a grid_px grid): 1 where no two
    share a texel, 2 where every texel is covered twice.

    >>> two = np.array([[[0, 0], [0.5, 0], [0, 0.5]], [[0.5, 0.5], [1, 0.5], [0.5, 1]]])
    >>> round(uv_layers(two), 1), round(uv_layers(np.concatenate([two, two])), 1)
    (1.0, 2.0)
    """
    import cv2

    uv = np.asarray(corner_uv, np.float64)
    area = 0.5 * np.abs((uv[:, 1, 0] - uv[:, 0, 0]) * (uv[:, 2, 1] - uv[:, 0, 1])
                        - (uv[:, 2, 0] - uv[:, 0, 0]) * (uv[:, 1, 1] - uv[:, 0, 1]))
    union = np.zeros((grid_px, grid_px), np.uint8)
    for tri in np.round(uv * grid_px - 0.5).astype(np.int32):
        cv2.fillConvexPoly(union, tri, 1)
    covered = union.mean()
    return float(area.sum() / covered) if covered > 0 else 0.0


def head_chart(head: HeadModel, texture_px: int) -> Chart:
    """The head model's own UVs where they lay its surfaces side by side (MAX_UV_LAYERS), else an xatlas atlas of its
    template."""
    if head.uv is not None and head.triangles_uv is not None and len(head.triangles_uv) == len(head.triangles):
        corner_uv = model_corner_uv(head)
        if uv_layers(corner_uv) <= MAX_UV_LAYERS:
            return split_seams(head.triangles, corner_uv, head.num_vertices, "head model")
    return split_seams(head.triangles, atlas_corner_uv(head.template, head.triangles, texture_px),
                       head.num_vertices, "xatlas")
