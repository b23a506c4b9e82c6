"""Per-vertex quantities of triangle meshes, as pure numpy functions."""

from __future__ import annotations

import numpy as np


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V,3); a vertex on no triangle gets (0, 0, 1).

    vertices: (V,3), triangles: (F,3), counter-clockwise seen from outside.
    """
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64)
    a = v[tri[:, 0]]
    face_n = cross(v[tri[:, 1]] - a, v[tri[:, 2]] - a)  # length = 2 * area
    corner = tri.T.ravel()  # every face's first corner, then every face's second, then third
    n = np.stack([np.bincount(corner, weights=np.tile(face_n[:, c], 3), minlength=len(v)) for c in range(3)], 1)
    length = np.sqrt(np.einsum("vc,vc->v", n, n))[:, None]
    out = np.where(length > 1e-20, n / np.maximum(length, 1e-20), [0.0, 0.0, 1.0])
    return out.astype(np.float32)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...,3) a x b, written out (np.cross moves axes about: slower over images and long lists).

    >>> cross(np.array([1.0, 0, 0]), np.array([0.0, 1, 0])).tolist()
    [0.0, 0.0, 1.0]
    """
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], -1)
