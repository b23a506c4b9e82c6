"""Iso-surfaces of a sampled field by marching tetrahedra: each cube of the grid split into six tetrahedra along its
main diagonal (so neighbouring cubes' faces split alike and the surface has no cracks), a triangle where one
corner of a tetrahedron differs from the other three, two where two do; vertices on the grid's edges where the
field crosses the level (linear), shared between the triangles that meet there; triangles turned so that their
normals point from the inside (values above the level) to the outside. No case tables beyond these three."""

from __future__ import annotations

import itertools

import numpy as np

# The six tetrahedra of a unit cube: from corner (0,0,0) to (1,1,1) along the axes in each order.
_TETS = np.array([[(0, 0, 0), tuple(np.eye(3, dtype=int)[p[0]]), tuple(np.eye(3, dtype=int)[p[0]] +
                   np.eye(3, dtype=int)[p[1]]), (1, 1, 1)] for p in itertools.permutations(range(3))])


def marching_tetrahedra(values: np.ndarray, level: float, origin: np.ndarray, spacing: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """values (X,Y,Z) sampled at origin + spacing * (i, j, k): the surface where they cross `level`, as vertices
    (V,3) and triangles (F,3), normals pointing from values above the level to values below.

    >>> v = np.zeros((3, 3, 3)); v[1, 1, 1] = 1.0  # one point above the level: a small closed surface about it
    >>> verts, tris = marching_tetrahedra(v, 0.5, np.zeros(3), 1.0)
    >>> bool(np.allclose(np.abs(verts - 1).max(1), 0.5)), len(tris) > 0
    (True, True)
    """
    X, Y, Z = values.shape
    inside = values > level
    idx = np.arange(X * Y * Z).reshape(X, Y, Z)
    cubes = np.stack(np.meshgrid(np.arange(X - 1), np.arange(Y - 1), np.arange(Z - 1), indexing="ij"), -1)
    cubes = cubes.reshape(-1, 3)
    # keep only cubes the surface passes through
    corners = cubes[:, None, :] + np.array(list(itertools.product((0, 1), repeat=3)))[None]
    c_in = inside[corners[..., 0], corners[..., 1], corners[..., 2]]
    cubes = cubes[c_in.any(1) & ~c_in.all(1)]
    if len(cubes) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    pts = cubes[:, None, None, :] + _TETS[None]  # (C,6,4,3)
    pts = pts.reshape(-1, 4, 3)
    vid = idx[pts[..., 0], pts[..., 1], pts[..., 2]]  # (T,4)
    vin = inside.reshape(-1)[vid]
    n_in = vin.sum(1)
    order = np.argsort(~vin, axis=1, kind="stable")  # inside corners first
    vid = np.take_along_axis(vid, order, 1)
    edges = []
    for count, pairs in ((1, [(0, 1), (0, 2), (0, 3)]), (3, [(0, 3), (1, 3), (2, 3)]),
                         (2, [(0, 2), (0, 3), (1, 3), (0, 2), (1, 3), (1, 2)])):
        sel = vid[n_in == count]
        tri = np.stack([np.stack([sel[:, a], sel[:, b]], -1) for a, b in pairs], 1)  # (n, 3k, 2)
        edges.append(tri.reshape(-1, 3, 2))
    tri_edges = np.concatenate(edges)  # (F,3,2): each triangle's corners as grid edges (inside end first)
    flat = values.reshape(-1)
    key = np.sort(tri_edges, -1)
    key = key[..., 0] * flat.size + key[..., 1]
    uniq, inverse = np.unique(key.reshape(-1), return_inverse=True)
    a, b = uniq // flat.size, uniq % flat.size
    fa, fb = flat[a], flat[b]
    t = np.clip((level - fa) / np.where(np.abs(fb - fa) > 1e-30, fb - fa, 1e-30), 0.0, 1.0)
    grid = lambda i: np.stack(np.unravel_index(i, values.shape), -1).astype(np.float64)
    verts = origin + spacing * (grid(a) + t[:, None] * (grid(b) - grid(a)))
    tris = inverse.reshape(-1, 3)
    # turn each triangle's normal towards its outside ends
    p = verts[tris]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    outward = (grid(tri_edges[..., 1].reshape(-1)) - grid(tri_edges[..., 0].reshape(-1))).reshape(-1, 3, 3).sum(1)
    flip = (normal * outward).sum(1) < 0
    tris[flip] = tris[flip][:, ::-1]
    keep = np.linalg.norm(normal, axis=1) > 1e-18 * spacing**2  # drop triangles that collapsed to a point
    return verts, tris[keep]
