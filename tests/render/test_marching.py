"""Iso-surfaces: placed on the grid in the world, at the level, the right way out; empty where there is none."""

from __future__ import annotations

import numpy as np

from render.marching import iso_surface


def test_a_plane_lies_where_a_linear_field_crosses_the_level():
    # values = 2 i on a 4x3x3 grid at origin (1, 2, 3), spacing 0.5: the level 3 is crossed at i = 1.5, which is
    # x = 1 + 0.5 * 1.5 = 1.75, over y in [2, 3] and z in [3, 4]
    values = np.broadcast_to(2.0 * np.arange(4)[:, None, None], (4, 3, 3)).copy()
    verts, tris = iso_surface(values, 3.0, np.array([1.0, 2.0, 3.0]), 0.5)
    np.testing.assert_allclose(verts[:, 0], 1.75, atol=1e-6)
    np.testing.assert_allclose([verts[:, 1].min(), verts[:, 1].max(), verts[:, 2].min(), verts[:, 2].max()],
                               [2.0, 3.0, 3.0, 4.0], atol=1e-6)
    # the values grow with x, so the inside (above the level) is +x and the normals point to -x
    p = verts[tris]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert len(tris) == 8 and np.all(normals[:, 0] < 0) and np.allclose(normals[:, 1:], 0, atol=1e-9)


def test_no_crossing_no_surface():
    for values in (np.zeros((3, 3, 3)), np.ones((3, 3, 3)), np.linspace(0, 1, 9).reshape(1, 3, 3)):
        verts, tris = iso_surface(values, 0.5, np.zeros(3), 1.0)
        assert verts.shape == (0, 3) and tris.shape == (0, 3)
