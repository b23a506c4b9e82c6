"""Meshes for other tools: marching tetrahedra checked on a sphere, and a primitives avatar exported with vertex
colours, loaded back with trimesh; a CoDyNeRF avatar's field as well."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from render.gl.raster import Rasterizer
from render.marching import marching_tetrahedra
from tests.conftest import CODYNERF_DEMO, DEMO


def test_a_sphere_comes_out_closed_outward_and_of_its_volume():
    g = np.linspace(-1.2, 1.2, 41)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    verts, tris = marching_tetrahedra(1.0 - np.sqrt(x * x + y * y + z * z), 0.0, np.full(3, -1.2), g[1] - g[0])
    m = trimesh.Trimesh(verts, tris, process=False)
    assert m.is_watertight and m.is_winding_consistent
    assert abs(m.volume - 4 / 3 * np.pi) < 0.01 * 4 / 3 * np.pi  # positive: the normals point out
    assert np.abs(np.linalg.norm(verts, axis=1) - 1.0).max() < 0.005  # on the sphere, to a 0.06 grid's linear error


def test_export_mesh_reloads_with_its_vertices_bounds_and_colours(tmp_path, capsys):
    from app.cli import main
    from models.avatars.registry import load_avatar

    out = tmp_path / "head.ply"
    assert main(["export-mesh", str(DEMO), "--out", str(out), "--resolution", "40"]) == 0
    said = capsys.readouterr().out
    m = trimesh.load(out, process=False)
    assert f"({len(m.vertices)} vertices, {len(m.faces)} triangles" in said
    assert m.is_watertight
    template = load_avatar(DEMO)[0].head_model.template
    assert np.all(m.bounds[0] > template.min(0) - 0.03) and np.all(m.bounds[1] < template.max(0) + 0.03)
    assert np.all(m.bounds[1] - m.bounds[0] > 0.8 * np.ptp(template, 0))  # the whole head, not a piece
    colours = np.asarray(m.visual.vertex_colors)[:, :3].astype(int)
    assert colours.std(0).max() > 5 and 40 < colours.mean() < 230  # a coloured head, not one flat value
    obj = tmp_path / "head.obj"
    assert main(["export-mesh", str(DEMO), "--out", str(obj), "--resolution", "24"]) == 0
    assert len(trimesh.load(obj, process=False).vertices) > 100


def test_codynerf_exports_its_soft_field_and_nerface_says_it_cannot(tmp_path, capsys, gl):
    """CoDyNeRF's field, sampled where its rays sample it: a closed surface round the whole head, within the shell
    about the mesh, at the level the command states (the demo's short training leaves a soft field, so half its
    highest density); a NerFACE avatar is refused with the reason, and nothing is written."""
    from app.cli import main
    from models.avatars.mesh import HALF_LIGHT_IN_1CM
    from models.avatars.registry import load_avatar, untrained_avatar
    from models.head.controls import Controls

    out = tmp_path / "c.ply"
    assert main(["export-mesh", str(CODYNERF_DEMO), "--out", str(out), "--resolution", "40"]) == 0
    said = capsys.readouterr().out
    level = float(said.split("density is ")[1].split(" per metre")[0])
    assert 0 < level <= HALF_LIGHT_IN_1CM
    m = trimesh.load(out, process=False)
    assert m.is_watertight and f"({len(m.vertices)} vertices" in said
    avatar = load_avatar(CODYNERF_DEMO)[0]
    template, shell = avatar.head_model.template, avatar.render_cfg.shell_m
    assert np.all(m.bounds[0] > template.min(0) - shell - 0.01) and np.all(m.bounds[1] < template.max(0) + shell + 0.01)
    assert np.all(m.bounds[1] - m.bounds[0] > 0.8 * np.ptp(template, 0))
    # the field at the vertices is at the level (to the grid's linear interpolation, 1 cm cells: within a quarter)
    field = avatar.mesh_field(avatar.card.at_rest(Controls()), Rasterizer(gl))
    at = field.density(torch.as_tensor(m.vertices[::50], dtype=torch.float32)).numpy()
    assert np.median(np.abs(at - level)) < 0.25 * level
    nerface = untrained_avatar("nerface", avatar.head_model)
    with pytest.raises(ValueError, match="nerface"):
        nerface.mesh_field(Controls(), None)
