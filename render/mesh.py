"""Per-vertex quantities of triangle meshes, as pure numpy functions."""

from __future__ import annotations

import numpy as np


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V,3); a vertex on no triangle gets (0, 0, 1).

    vertices: (V,3), triangles: (F,3), counter-clockwise seen from outside.
    """
    v = np.asarray(vertices, np.float64)
    tri = v[triangles]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 * area
    idx = np.asarray(triangles, np.int64).ravel()
    fn = np.repeat(face_n, 3, axis=0)
    n = np.stack([np.bincount(idx, weights=fn[:, c], minlength=len(v)) for c in range(3)], 1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(length > 1e-20, n / np.maximum(length, 1e-20), [0.0, 0.0, 1.0])
    return out.astype(np.float32)
