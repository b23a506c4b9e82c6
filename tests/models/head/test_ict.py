"""ICT-FaceKit: the npz and the FaceXModel/ OBJ folder give the same model; rigid root, eyeball gaze,
expressions by name."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from models.head.controls import Controls, ControlsError
from models.head.head import Head
from models.head.ict import NEUTRAL_OBJ, load_ict_folder
from models.head.model import HeadModelError


def write_obj_cm(path, verts_m, faces):
    lines = [f"v {x * 100:.6f} {y * 100:.6f} {z * 100:.6f}" for x, y, z in verts_m]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def facex_folder(ict_npz, tmp_path_factory):
    """A FaceXModel/-style folder written from the npz: neutral, 3 expressions, 2 identities, in cm."""
    folder = tmp_path_factory.mktemp("FaceXModel")
    d = np.load(ict_npz)
    n = d["neutral_m"].astype(np.float64)
    write_obj_cm(folder / NEUTRAL_OBJ, n, d["triangles"])
    names = list(d["expr_names"])
    for name in ("jawOpen", "eyeBlink_L", "mouthSmile_R"):
        write_obj_cm(folder / f"{name}.obj", n + d["expr_deltas_m"][names.index(name)], d["triangles"])
    for k in range(2):
        write_obj_cm(folder / f"identity{k:03d}.obj", n + d["id_deltas_m"][k], d["triangles"])
    return folder


def test_folder_matches_npz(ict_model, facex_folder):
    m = load_ict_folder(facex_folder)
    np.testing.assert_allclose(m.template, ict_model.template, atol=1e-7)
    np.testing.assert_array_equal(m.triangles, ict_model.triangles)
    assert m.expr_names == ("eyeBlink_L", "jawOpen", "mouthSmile_R")
    for k, name in enumerate(m.expr_names):
        np.testing.assert_allclose(m.expr_basis[..., k], ict_model.expr_basis[..., ict_model.expression_index(name)],
                                   atol=1e-7)
    np.testing.assert_allclose(m.shape_basis, ict_model.shape_basis[..., :2], atol=1e-7)
    # Posed through the same controls, the two give the same mesh.
    c_npz = Controls(shape=np.array([1.5, -2.0]), root=np.array([0.1, 0.4, 0.0]), gaze_left=np.array([0, 0.3, 0]))
    c_npz = c_npz.with_expression(ict_model, {"jawOpen": 0.7, "eyeBlink_L": 1.0})
    c_obj = Controls(shape=np.array([1.5, -2.0]), root=np.array([0.1, 0.4, 0.0]), gaze_left=np.array([0, 0.3, 0]))
    c_obj = c_obj.with_expression(m, {"jawOpen": 0.7, "eyeBlink_L": 1.0})
    v1 = Head(ict_model).pose(c_npz)[0]
    v2 = Head(m).pose(c_obj)[0]
    torch.testing.assert_close(v1, v2, atol=2e-6, rtol=0)


def test_folder_without_neutral(tmp_path):
    (tmp_path / "jawOpen.obj").write_text("v 0 0 0\n")
    with pytest.raises(HeadModelError, match=f"not an ICT FaceXModel folder, {NEUTRAL_OBJ} is missing"):
        load_ict_folder(tmp_path)


def test_root_pose_is_rigid(ict_model):
    head = Head(ict_model, dtype=torch.float64)
    v0 = head.pose(Controls())[0][0]
    v1 = head.pose(Controls(root=np.array([0.3, -0.7, 0.2]), translation=np.array([0.01, 0.02, -0.03])))[0][0]
    idx = torch.randperm(len(v0), generator=torch.Generator().manual_seed(0))[:500]
    d0 = torch.cdist(v0[idx], v0[idx])
    d1 = torch.cdist(v1[idx], v1[idx])
    torch.testing.assert_close(d1, d0, atol=1e-6, rtol=0)


def test_gaze_turns_each_eyeball_about_its_centre(ict_model):
    head = Head(ict_model, dtype=torch.float64)
    v0 = head.pose(Controls())[0][0]
    v1 = head.pose(Controls(gaze_left=np.array([0.0, 0.35, 0.0])))[0][0]
    lo, hi = 14062, 15632  # eyeball_left
    c0 = v0[lo:hi].mean(0)
    torch.testing.assert_close(v1[lo:hi].mean(0), c0, atol=1e-9, rtol=0)
    torch.testing.assert_close((v1[lo:hi] - c0).norm(dim=1), (v0[lo:hi] - c0).norm(dim=1), atol=1e-9, rtol=0)
    # The cornea (the eyeball's front-most point) turns towards +x: the subject's left.
    front = int(torch.argmax(v0[lo:hi, 2]))
    assert v1[lo + front, 0] - v0[lo + front, 0] > 0.003
    # Nothing else moves.
    torch.testing.assert_close(v1[:lo], v0[:lo], atol=0, rtol=0)
    torch.testing.assert_close(v1[hi:], v0[hi:], atol=0, rtol=0)


def test_expressions_by_name(ict_model):
    head = Head(ict_model)
    lm0 = head.pose(Controls())[2][0]
    lm1 = head.pose(Controls().with_expression(ict_model, {"jawOpen": 1.0}))[2][0]
    # Landmark 8 is the chin, 57 the lower lip's middle: the jaw drops them by centimetres.
    assert lm0[8, 1] - lm1[8, 1] > 0.01
    assert lm0[57, 1] - lm1[57, 1] > 0.01
    with pytest.raises(ControlsError, match="no expression 'smile'"):
        Controls().with_expression(ict_model, {"smile": 1.0})


def test_no_neck_or_jaw_joint(ict_model):
    with pytest.raises(ControlsError, match="no 'jaw' joint"):
        Head(ict_model).pose(Controls(jaw=np.array([0.2, 0, 0])))


def test_demo_head_is_one_ict_identity(ict_model):
    """`--head demo` is ICT's neutral head with the identity `synth --identity K` draws added in (K kept in the
    npz), the same 53 expression blend shapes, no identity components, and ICT-FaceKit's licence beside it."""
    from models.capture.synthetic import identity_coefficients
    from models.head.sources import DEMO_HEAD_PATH, load_head

    demo = load_head("demo")
    seed = int(np.load(DEMO_HEAD_PATH)["identity_seed"])
    shape = identity_coefficients(ict_model, seed)
    assert seed > 0 and np.abs(shape).max() > 0.1  # a person, not ICT's mean head
    want = ict_model.template + np.einsum("vcs,s->vc", ict_model.shape_basis, shape)
    np.testing.assert_allclose(demo.template, want, atol=1e-6)
    assert demo.num_shape == 0 and demo.expr_names == ict_model.expr_names
    np.testing.assert_array_equal(demo.expr_basis, ict_model.expr_basis)
    np.testing.assert_array_equal(demo.triangles, ict_model.triangles)
    jaw = ict_model.expr_names.index("jawOpen")
    posed = Head(demo).pose(Controls(expression=np.eye(53, dtype=np.float32)[jaw]))[0][0].numpy()
    np.testing.assert_allclose(posed - demo.template, ict_model.expr_basis[:, :, jaw], atol=1e-6)
    assert "MIT License" in (DEMO_HEAD_PATH.parent / "LICENSE").read_text()
