"""Iso-surfaces of a sampled field: scikit-image's marching cubes (Lewiner et al. 2003, whose case tables resolve the
ambiguous faces the same way in neighbouring cubes, so the surface has no cracks), placed in the world and turned
so that triangle normals point from the inside (values above the level) to the outside."""

from __future__ import annotations

import numpy as np


def iso_surface(values: np.ndarray, level: float, origin: np.ndarray, spacing: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """values (X,Y,Z) sampled at origin + spacing * (i, j, k): the surface where they cross `level`, as vertices
    (V,3) float64 and triangles (F,3) int64, counter-clockwise seen from outside, none of zero area; empty where the
    values do not cross the level. The vertices lie on the grid's edges, linear between the two samples, but for one
    more inside each cube whose corners leave the surface's shape ambiguous (a few in a hundred on noise, fewer on a
    smooth field).

    >>> v = np.zeros((3, 3, 3)); v[1, 1, 1] = 1.0  # one point above the level: a small closed surface about it
    >>> verts, tris = iso_surface(v, 0.5, np.zeros(3), 1.0)
    >>> bool(np.allclose(np.abs(verts - 1).max(1), 0.5)), len(tris)
    (True, 8)
    """
    from skimage.measure import marching_cubes  # 0.3 s to import: only when a mesh is made

    inside = values > level
    if min(values.shape) < 2 or not inside.any() or inside.all():
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    # "ascent": scikit-image winds its triangles by the left-hand rule, so its default points them inwards here
    verts, tris, _, _ = marching_cubes(values, level, gradient_direction="ascent", allow_degenerate=False)
    return origin + spacing * verts.astype(np.float64), tris.astype(np.int64)


marching_tetrahedra = iso_surface
"""The name of the marching tetrahedra that this replaced, which tests/models/avatars/primitives/test_mesh.py
imports."""
