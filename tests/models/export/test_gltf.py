"""The .glb read back by readers other than its writer (pygltflib's parser with our own accessor decoding, trimesh,
the Khronos validator): the head model's rest template, its expressions as morph targets, its skeleton skinning as
the head model's own skinning does, its texture, and animation samplers."""

from __future__ import annotations

import itertools

import numpy as np
import pygltflib
import pytest
import torch

from models.export.gltf import MeshAsset, glb_bytes
from models.export.keys import Clip, morph_keys, pose_frames
from models.head.controls import Controls
from models.head.head import Head
from tests.models.export.reading import accessor, cubic_spline, skinned, texture, validator_report


@pytest.fixture(scope="module")
def demo_gltf(demo_export):
    return pygltflib.GLTF2.load(str(demo_export[1]))


def test_the_file_passes_the_khronos_validator_with_no_errors_or_warnings(demo_export):
    report = validator_report(demo_export[1])
    assert report["numErrors"] == 0, report["messages"]
    assert report["numWarnings"] == 0, report["messages"]


def test_positions_are_the_head_models_rest_template_in_its_order_then_the_seam_copies(demo_gltf, demo_avatar):
    head = demo_avatar.head_model
    prim = demo_gltf.meshes[0].primitives[0]
    positions = accessor(demo_gltf, prim.attributes.POSITION)
    copies = np.asarray(demo_gltf.meshes[0].extras["seam_vertex_of"])
    assert len(positions) == head.num_vertices + len(copies) == 15069  # the built-in head's 14832 and 237 copies
    np.testing.assert_allclose(positions[:head.num_vertices], head.template, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(positions[head.num_vertices:], head.template[copies])
    # The triangles are the head model's, in its order, each corner the vertex or a copy of it.
    tris = accessor(demo_gltf, prim.indices).reshape(-1, 3)
    source = np.concatenate([np.arange(head.num_vertices), copies])
    np.testing.assert_array_equal(source[tris], head.triangles)


def test_trimesh_reads_the_same_mesh_and_texture_coordinates(demo_export):
    import trimesh

    done, path = demo_export
    scene = trimesh.load(path, process=False)
    (mesh,) = scene.geometry.values()
    np.testing.assert_allclose(mesh.vertices, done.mesh.positions, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, done.chart.triangles)
    # trimesh keeps OBJ's texture convention (v up): glTF's v turned over.
    np.testing.assert_allclose(mesh.visual.uv, np.stack([done.chart.uv[:, 0], 1 - done.chart.uv[:, 1]], 1), atol=1e-6)
    assert mesh.visual.material.baseColorTexture.size == (256, 256)
    assert set(scene.graph.nodes) >= {"root", "neck", "jaw", "eye_l", "eye_r"}


def test_morph_targets_are_the_expression_basis_named_as_the_sliders(demo_gltf, demo_avatar):
    head = demo_avatar.head_model
    mesh = demo_gltf.meshes[0]
    assert mesh.extras["targetNames"] == list(head.expr_names)
    assert len(mesh.primitives[0].targets) == head.num_expression == 16
    assert mesh.weights == [0.0] * 16
    copies = np.asarray(mesh.extras["seam_vertex_of"])
    for k, target in enumerate(mesh.primitives[0].targets):
        deltas = accessor(demo_gltf, target["POSITION"])
        np.testing.assert_array_equal(deltas[:head.num_vertices], head.expr_basis[:, :, k])
        np.testing.assert_array_equal(deltas[head.num_vertices:], head.expr_basis[copies, :, k])
    # Blinks move only the lids (0.7% of the vertices): written sparse, a fraction of the dense size.
    k = head.expression_index("blink_L")
    blink = demo_gltf.accessors[mesh.primitives[0].targets[k]["POSITION"]]
    moved = np.any(head.expr_basis[:, :, k] != 0, 1)
    assert blink.sparse is not None and blink.sparse.count == moved.sum() + moved[copies].sum() < 0.01 * 15069


def test_a_morph_weight_of_one_is_the_head_model_with_that_expression(demo_gltf, demo_avatar):
    head = demo_avatar.head_model
    prim = demo_gltf.meshes[0].primitives[0]
    k = head.expression_index("smile_L")
    morphed = accessor(demo_gltf, prim.attributes.POSITION) + accessor(demo_gltf, prim.targets[k]["POSITION"])
    expr = np.zeros(head.num_expression, np.float32)
    expr[k] = 1.0
    verts = Head(head).pose(Controls(expression=expr))[0][0].numpy()
    np.testing.assert_allclose(morphed[:head.num_vertices], verts, rtol=0, atol=2e-6)


@pytest.mark.parametrize("pose", [{"jaw": [0.3, 0, 0]}, {"root": [0.1, 0.6, -0.2], "neck": [0.2, 0, 0.1]},
                                  {"gaze_left": [0, 0.4, 0], "gaze_right": [0.2, -0.3, 0], "jaw": [0.25, 0.05, 0]}],
                         ids=["jaw", "head_and_neck", "eyes_and_jaw"])
def test_the_skeleton_skins_as_the_head_model_does(demo_gltf, demo_avatar, pose):
    """glTF's skinning of the file's joints at the head model's joint rotations lands where lbs puts the vertices
    (the built-in head has no pose correctives and at most 3 joints a vertex: the same up to float error)."""
    head = demo_avatar.head_model
    controls = Controls(**{k: np.asarray(v, np.float32) for k, v in pose.items()})
    full_pose = Head(head).full_pose([controls])[0].numpy()  # (J,3)
    frames = pose_frames(np.zeros(1), full_pose[None])
    rotations = {1 + j: q[0] for j, q in frames.rotations.items()}  # joint j is node j + 1
    positions = accessor(demo_gltf, demo_gltf.meshes[0].primitives[0].attributes.POSITION).astype(np.float64)
    got = skinned(demo_gltf, positions, rotations)[:head.num_vertices]
    with torch.no_grad():
        want = Head(head, torch.float64).pose(controls)[0][0].numpy()
    moved = np.linalg.norm(want - head.template, axis=1).max()
    assert moved > 0.005  # the pose moves something
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)


def test_the_texture_is_the_baked_one(demo_gltf, demo_export):
    np.testing.assert_array_equal(texture(demo_gltf), demo_export[0].texture.image)
    material = demo_gltf.materials[demo_gltf.meshes[0].primitives[0].material]
    assert "KHR_materials_unlit" in material.extensions and demo_gltf.extensionsUsed == ["KHR_materials_unlit"]
    assert material.pbrMetallicRoughness.metallicFactor == 0.0


def test_clips_read_back_as_written_and_pass_the_validator(demo_export, tmp_path):
    """A clip's samplers (smooth expressions as CUBICSPLINE, rotations as LINEAR) read back to the values given,
    and the spline played as glTF plays it is the smoothstep between the keys."""
    done = demo_export[0]
    keys = {0: [(0.0, 0.0), (1.0, 1.0), (2.5, 0.25)], 8: [(0.5, 0.0), (1.5, 1.0)]}
    morph = morph_keys(keys, 16, "smooth")
    times = np.arange(30) / 10.0
    jaw = np.zeros((30, 5, 3))
    jaw[:, 2, 0] = np.linspace(0, 0.3, 30)
    clip = Clip("talk", morph, pose_frames(times, jaw))
    path = tmp_path / "clip.glb"
    path.write_bytes(glb_bytes(done.mesh, (clip,)))
    gltf = pygltflib.GLTF2.load(str(path))
    (anim,) = gltf.animations
    weights = next(c for c in anim.channels if c.target.path == "weights")
    s = anim.samplers[weights.sampler]
    assert s.interpolation == "CUBICSPLINE" and weights.target.node == 0
    t = accessor(gltf, s.input)[:, 0]
    np.testing.assert_array_equal(t, [0.0, 0.5, 1.0, 1.5, 2.5])  # the union of the two channels' key times
    out = accessor(gltf, s.output).reshape(len(t), 3, 16)
    np.testing.assert_allclose(out[:, 1, 0], [0.0, 0.5, 1.0, 1 - 0.75 * 7 / 27, 0.25], atol=1e-7)  # e(1/3) = 7/27
    for u in np.linspace(-0.5, 3.0, 71):
        want0 = value(keys[0], u)
        want8 = value(keys[8], u)
        got = cubic_spline(t, out, u)
        assert got[0] == pytest.approx(want0, abs=2e-6) and got[8] == pytest.approx(want8, abs=2e-6)
    (rotation,) = [c for c in anim.channels if c.target.path == "rotation"]
    assert rotation.target.node == 3 and gltf.nodes[3].name == "jaw"
    q = accessor(gltf, anim.samplers[rotation.sampler].output)
    np.testing.assert_allclose(q[-1], [np.sin(0.15), 0, 0, np.cos(0.15)], atol=1e-7)  # 0.3 rad about +x
    report = validator_report(path)
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["messages"]


def value(keys, t):
    """A smooth channel by hand: hold outside the keys, v0 + (v1 - v0)(3u^2 - 2u^3) between."""
    if t <= keys[0][0]:
        return keys[0][1]
    for (t0, v0), (t1, v1) in itertools.pairwise(keys):
        if t <= t1:
            u = (t - t0) / (t1 - t0)
            return v0 + (v1 - v0) * u * u * (3 - 2 * u)
    return keys[-1][1]


def test_a_head_model_with_a_root_alone_has_no_skin():
    """ICT-like: one joint; the file has no skin, no joint nodes, no JOINTS_0."""
    mesh = MeshAsset("tri", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
                     np.tile(np.float32([0, 0, 1]), (3, 1)), np.array([[0, 0], [1, 0], [0, 1]], np.float32),
                     np.array([[0, 1, 2]]), ("up",), np.array([[[0, 0, 0], [0, 0, 0], [0, 0.5, 0]]], np.float32))
    gltf = pygltflib.GLTF2.load_from_bytes(glb_bytes(mesh))
    assert gltf.skins == [] and len(gltf.nodes) == 1 and gltf.meshes[0].primitives[0].attributes.JOINTS_0 is None
    np.testing.assert_array_equal(accessor(gltf, gltf.meshes[0].primitives[0].targets[0]["POSITION"])[2], [0, 0.5, 0])


def test_an_ict_head_writes_a_valid_file_with_its_eyes_as_a_skeleton(ict_model, tmp_path):
    """ICT-FaceKit: its own UVs over two UDIM tiles packed on one texture, 53 expressions, and a root with two eye
    joints (no jaw: its mouth opens through jawOpen)."""
    from models.export.avatar_gltf import head_mesh
    from models.export.chart import head_chart

    mesh = head_mesh(ict_model, head_chart(ict_model, 512), texture_png=None)
    path = tmp_path / "ict.glb"
    path.write_bytes(glb_bytes(mesh))
    gltf = pygltflib.GLTF2.load(str(path))
    assert [n.name for n in gltf.nodes] == ["head", "root", "eye_l", "eye_r"]
    assert gltf.meshes[0].extras["targetNames"] == list(ict_model.expr_names) and len(ict_model.expr_names) == 53
    positions = accessor(gltf, gltf.meshes[0].primitives[0].attributes.POSITION)
    np.testing.assert_allclose(positions[:ict_model.num_vertices], ict_model.template, rtol=0, atol=1e-6)
    report = validator_report(path)
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["messages"]
