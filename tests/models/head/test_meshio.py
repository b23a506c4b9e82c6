"""Meshes written for other tools read back with trimesh as they were given: vertex order, triangles, colours."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from models.head.meshio import mesh_bytes


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".OBJ"])
def test_a_coloured_mesh_reads_back_in_its_order(suffix):
    # four vertices in an order no processing would keep (the last one first when sorted), two triangles
    v = np.array([[0.3, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.1], [-0.1, -0.1, -0.1]])
    f = np.array([[0, 1, 2], [3, 1, 0]])
    c = np.array([[255, 0, 0], [0, 128, 0], [0, 0, 9], [1, 2, 3]], np.uint8)
    back = trimesh.load(io.BytesIO(mesh_bytes(suffix, v, f, c)), file_type=suffix[1:].lower(), process=False,
                        maintain_order=True)
    np.testing.assert_allclose(back.vertices, v, atol=1e-7)  # PLY's float32: 0.3 within 1.2e-8
    np.testing.assert_array_equal(back.faces, f)
    # OBJ carries colours as fractions (0.50196078 for 128): they come back to the same byte
    np.testing.assert_array_equal(np.asarray(back.visual.vertex_colors)[:, :3], c)


def test_other_suffixes_are_refused():
    with pytest.raises(ValueError, match=r"\.obj or \.ply, not '\.stl'"):
        mesh_bytes(".stl", np.zeros((3, 3)), np.array([[0, 1, 2]]))
