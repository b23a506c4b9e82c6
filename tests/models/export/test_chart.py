"""Texture charts: the head model's own UVs (turned to glTF's v down, UDIM tiles packed), xatlas where a head model
has none, and the vertices split along the seams."""

from __future__ import annotations

import numpy as np
import pytest

from models.export.bake import texel_surface
from models.export.chart import MAX_UV_LAYERS, head_chart, model_corner_uv, split_seams, uv_layers
from models.head.model import HeadModel


def test_the_builtin_heads_chart_is_its_own_uvs_turned_over(builtin_model):
    chart = head_chart(builtin_model, 256)
    assert chart.source == "head model"
    V = builtin_model.num_vertices
    np.testing.assert_array_equal(chart.vertex_of[:V], np.arange(V))
    np.testing.assert_array_equal(chart.vertex_of[chart.triangles], builtin_model.triangles)
    # Each corner's texture coordinate is the head model's, v turned over (OBJ's v up to glTF's v down).
    own = builtin_model.uv[builtin_model.triangles_uv]
    np.testing.assert_array_equal(chart.uv[chart.triangles], np.stack([own[..., 0], 1 - own[..., 1]], -1))
    # 237 vertices lie on a seam (the skin's wrap-around at the back, the eyeballs' and the crown's): one copy each,
    # and nothing is copied that need not be.
    assert chart.seam_copies == 237
    pairs = np.unique(np.column_stack([builtin_model.triangles.ravel(), builtin_model.triangles_uv.ravel()]), axis=0)
    assert len(pairs) == V + chart.seam_copies


def test_udim_tiles_are_packed_into_one_square_texture():
    """Five tiles along u go on a grid of 3 columns and 2 rows: tile (k, 0) to cell (k % 3, k // 3), u scaled 1/3 and
    v 1/2; then v is turned over."""
    tris = np.arange(15).reshape(5, 3)
    corner = np.array([[0.1, 0.2], [0.9, 0.2], [0.5, 0.8]])
    uv = np.concatenate([corner + [k, 0] for k in range(5)])
    head = _tiny_head(np.zeros((15, 3)), tris, uv=uv, triangles_uv=tris)
    got = model_corner_uv(head)
    # tile 4 -> cell (1, 1): u = (1 + 0.1) / 3, v = 1 - (1 + 0.2) / 2; tile 2 -> cell (2, 0)
    np.testing.assert_allclose(got[4, 0], [1.1 / 3, 1 - 1.2 / 2], atol=1e-6)
    np.testing.assert_allclose(got[2, 2], [2.5 / 3, 1 - 0.8 / 2], atol=1e-6)
    assert got.min() >= 0 and got.max() <= 1


def test_ict_uvs_make_one_texture(ict_model):
    """ICT's triangles lie on two UDIM tiles (u in [0, 2)): side by side, each half the texture's width. (Its
    sockets and eyeballs share the face's texels there, so the bake charts ICT with xatlas: the test below.)"""
    corner = model_corner_uv(ict_model)
    assert 0 <= corner.min() and corner.max() <= 1
    own = ict_model.uv[ict_model.triangles_uv]
    np.testing.assert_allclose(corner, np.stack([own[..., 0] / 2, 1 - own[..., 1]], -1), atol=1e-6)
    chart = head_chart(ict_model, 256)
    assert chart.source == "xatlas"
    np.testing.assert_array_equal(chart.vertex_of[chart.triangles], ict_model.triangles)


def test_a_head_model_without_uvs_gets_an_xatlas_atlas_whose_charts_do_not_overlap():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    head = _tiny_head(np.asarray(sphere.vertices, np.float32), np.asarray(sphere.faces))
    chart = head_chart(head, 128)
    assert chart.source == "xatlas" and chart.seam_copies > 0
    np.testing.assert_array_equal(chart.vertex_of[chart.triangles], head.triangles)
    assert 0 <= chart.uv.min() and chart.uv.max() <= 1
    # No two triangles share a texel: each texel's centre lies inside one triangle at most.
    covered = texel_surface(chart.uv, chart.triangles, 128, reach_px=0.0).covered
    a, b, c = chart.uv[chart.triangles].transpose(1, 0, 2)
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]).sum()
    assert covered.mean() == pytest.approx(area, rel=0.05)  # texels covered ~ the charts' area: none counted twice


def test_a_vertex_on_no_triangle_keeps_its_place():
    chart = split_seams(np.array([[0, 2, 3]]), np.zeros((1, 3, 2), np.float32), 5, "test")
    np.testing.assert_array_equal(chart.vertex_of, np.arange(5))
    np.testing.assert_array_equal(chart.triangles, [[0, 2, 3]])


def _tiny_head(template: np.ndarray, triangles: np.ndarray, **uv) -> HeadModel:
    V = len(template)
    return HeadModel(name="tiny", template=np.asarray(template, np.float32), triangles=np.asarray(triangles, np.int32),
                     shape_basis=np.zeros((V, 3, 0), np.float32), expr_basis=np.zeros((V, 3, 1), np.float32),
                     J_regressor=np.full((1, V), 1.0 / V, np.float32), weights=np.ones((V, 1), np.float32),
                     parents=np.array([-1]), joint_names=("root",), pose_basis=np.zeros((V, 3, 0), np.float32),
                     **uv)



def test_a_layout_that_lays_surfaces_on_each_other_gets_an_atlas(builtin_model):
    """ICT's UVs put the mouth and eye sockets and the eyeballs on the face's texels (2.9 layers): baked on them, the
    face took the sockets' colours; the demo's head gets an xatlas atlas, where every texel is one surface's. The
    built-in head's layout (1.15) stays."""
    from models.head.sources import load_head

    demo = load_head("demo")
    assert uv_layers(model_corner_uv(demo)) > 2.5 > MAX_UV_LAYERS >= uv_layers(model_corner_uv(builtin_model))
    chart = head_chart(demo, 256)
    assert chart.source == "xatlas" and uv_layers(chart.uv[chart.triangles]) < 1.05
    assert head_chart(builtin_model, 256).source == "head model"
