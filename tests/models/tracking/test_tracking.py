"""Tracking's parts: the canonical mesh read from the bundle, similarity alignment, landmark correspondences
for the built-in head, ICT and FLAME-format files, and the fitter recovering known controls from landmarks."""

from __future__ import annotations

import math
import struct
import zipfile

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from models.head.controls import Controls
from models.head.head import Head
from models.head.sources import load_head
from models.tracking.blendshapes import arkit_names, expression_from_scores, gaze_from_scores
from models.tracking.canonical import BundleError, canonical_face_mesh, message_fields
from models.tracking.correspond import ANCHORS, correspond, head_landmarks, umeyama
from models.tracking.fit import FitConfig, FitError, Intrinsics, fit, project
from tests.models.head.flame_files import write_flame_from_head


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def test_wire_format_hand_worked():
    # field 1 varint 300 (0x08 0xAC 0x02); field 2 bytes "hi"; field 3 fixed32 1.5.
    buf = b"\x08\xac\x02" + b"\x12\x02hi" + b"\x1d" + struct.pack("<f", 1.5)
    assert message_fields(buf) == [(1, 0, 300), (2, 2, b"hi"), (3, 5, struct.pack("<f", 1.5))]


def test_canonical_mesh_from_a_hand_made_bundle(tmp_path):
    """A bundle holding a 468-vertex mesh, vertex floats unpacked and indices packed: read back exactly."""
    rng = np.random.default_rng(0)
    verts = rng.normal(0, 5, (468, 5)).astype(np.float32)  # x, y, z (cm), u, v
    tris = rng.integers(0, 468, (10, 3))
    vb = b"".join(b"\x1d" + struct.pack("<f", float(x)) for x in verts.ravel())
    packed = b"".join(_varint(int(i)) for i in tris.ravel())
    mesh = b"\x08\x00" + vb + b"\x22" + _varint(len(packed)) + packed
    meta = b"\x0a" + _varint(len(mesh)) + mesh + b"\x12\x03\x08\x01\x10"
    bundle = tmp_path / "face.task"
    with zipfile.ZipFile(bundle, "w") as z:
        z.writestr("geometry_pipeline_metadata_landmarks.binarypb", meta)
    v, t = canonical_face_mesh(bundle)
    np.testing.assert_array_equal(v, verts[:, :3] / 100.0)
    np.testing.assert_array_equal(t, tris)
    (tmp_path / "junk.task").write_bytes(b"not a zip")
    with pytest.raises(BundleError, match=r"junk\.task"):
        canonical_face_mesh(tmp_path / "junk.task")


def test_canonical_mesh_matches_mediapipes_obj(landmarker):
    """The mesh read out of the real bundle against the OBJ MediaPipe publishes (an independent copy)."""
    import trimesh

    v, t = canonical_face_mesh(landmarker)
    obj = trimesh.load(landmarker.parent / "canonical_face_model.obj", process=False)
    np.testing.assert_allclose(v, np.asarray(obj.vertices) / 100.0, atol=1e-7)
    np.testing.assert_array_equal(t, np.asarray(obj.faces))


def test_umeyama_recovers_a_known_similarity():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(30, 3))
    R = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix()
    dst = 1.7 * src @ R.T + np.array([0.1, -2.0, 3.0])
    s, R2, t = umeyama(src, dst)
    assert s == pytest.approx(1.7, rel=1e-9)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t, [0.1, -2.0, 3.0], atol=1e-9)


def test_blendshape_names():
    assert arkit_names("eyeBlink_L") == ("eyeBlinkLeft", "eyeBlink")
    assert arkit_names("jawOpen") == ("jawOpen",)
    # Looking to the subject's left: the left eye looks out, the right eye in; both turn about +y.
    g = gaze_from_scores({"eyeLookOutLeft": 1.0, "eyeLookInRight": 1.0})
    assert g[0, 1] > 0.4 and g[1, 1] > 0.4 and abs(g[:, 0]).max() == 0


def test_blendshape_scores_start_ict_and_builtin_expressions(ict_model, builtin_model):
    scores = {"eyeBlinkLeft": 0.8, "jawOpen": 0.5, "cheekPuff": 0.3, "mouthSmileRight": 0.6}
    e = expression_from_scores(ict_model, scores)
    idx = ict_model.expression_index
    assert (e[idx("eyeBlink_L")], e[idx("jawOpen")], e[idx("cheekPuff_R")], e[idx("mouthSmile_R")]) == \
        pytest.approx((0.8, 0.5, 0.3, 0.6))
    assert e[idx("eyeBlink_R")] == 0
    b = expression_from_scores(builtin_model, scores)
    assert b[builtin_model.expression_index("blink_L")] == pytest.approx(0.8)
    assert b[builtin_model.expression_index("smile_R")] == pytest.approx(0.6)


@pytest.fixture(scope="module")
def flame_model(tmp_path_factory, builtin_model):
    path = write_flame_from_head(tmp_path_factory.mktemp("flame"), builtin_model)
    return load_head(f"flame:{path}")


@pytest.mark.parametrize("which", ["builtin", "ict", "flame"])
def test_correspondences_put_landmarks_on_the_right_features(which, landmarker, builtin_model, flame_model,
                                                            request):
    """MediaPipe's anatomical anchors land within 1 cm of the head model's own iBUG landmarks (4 mm in the
    median: the two schemes place points like the base of the nose differently), and most of the 468 points
    find a vertex within 8 mm."""
    model = {"builtin": builtin_model, "flame": flame_model}.get(which) or request.getfixturevalue("ict_model")
    canonical, _ = canonical_face_mesh(landmarker)
    c = correspond(model, canonical)
    assert len(c.mp_ids) >= 440, len(c.mp_ids)
    assert np.median(c.gap_m) < 0.004
    lms = head_landmarks(model, model.template)
    ids = dict(zip(c.mp_ids.tolist(), c.vertex_ids.tolist(), strict=True))
    gaps = {(mp, ibug): float(np.linalg.norm(model.template[ids[mp]] - lms[ibug])) for mp, ibug in ANCHORS.items()
            if ibug in lms and mp in ids}
    assert len(gaps) >= 8
    assert max(gaps.values()) < 0.01 and np.median(list(gaps.values())) < 0.004, gaps


def synthetic_targets(model, controls: list[Controls], vertex_ids: np.ndarray, k: Intrinsics) -> np.ndarray:
    with torch.inference_mode():
        verts = Head(model).pose(controls)[0]
    return project(verts[:, vertex_ids], k).numpy()


@pytest.mark.parametrize("which", ["builtin", "flame"])
def test_fit_recovers_known_pose_jaw_and_expression(which, builtin_model, flame_model):
    """Landmarks projected from known controls (20 frames: head turns, jaw, expressions); the fit, started
    from zero expression and PnP, reprojects within 0.3 px (256 px images) and recovers head rotation within
    1.5 degrees, translation within 1 cm, jaw within 0.05 rad, the expression's deformation of the head within
    1 mm (99th percentile over vertices and frames) and its weights within a mean absolute error of 0.08 (median
    over frames; measured 0.012 built-in, 0.056 FLAME, whose unnamed components may go negative: some
    combinations deform alike, which is why the deformation is the tighter check)."""
    model = builtin_model if which == "builtin" else flame_model
    rng = np.random.default_rng(4)
    n = 20
    E = model.num_expression
    # Points that see every expression (the 12 vertices each moves most), as MediaPipe's dense landmarks do
    # on a face, and 150 others.
    moved = np.linalg.norm(model.expr_basis[..., :16], axis=1)  # (V,16)
    ids = np.unique(np.concatenate([np.argsort(-moved, 0)[:12].ravel(),
                                    rng.choice(len(model.template), 150, replace=False)])).astype(int)
    k = Intrinsics(700.0, 700.0, 128.0, 128.0)
    truth = []
    for i in range(n):
        expr = np.zeros(E, np.float32)
        active = rng.choice(min(E, 16), 3, replace=False)
        expr[active] = rng.uniform(0.2, 0.8, 3)
        yaw, pitch = 0.4 * math.sin(i / 3), 0.2 * math.cos(i / 4)
        truth.append(Controls(expression=expr, root=np.array([pitch, yaw, 0.05], np.float32),
                              jaw=np.array([0.15 * (i % 3 == 0), 0, 0], np.float32),
                              translation=np.array([0.01, -0.02, -0.55], np.float32)))
    targets = synthetic_targets(model, truth, ids, k)
    r = fit(model, ids, targets, k, cfg=FitConfig(iterations=300, shape_components=0, smooth_rotation=0.0,
                                                  smooth_translation=0.0, smooth_expression=0.0))
    assert np.median(r.error_px) < 0.3, np.median(r.error_px)
    for c, t in zip(r.controls, truth, strict=True):
        R1 = Rotation.from_rotvec(c.root)
        R2 = Rotation.from_rotvec(t.root)
        assert np.degrees((R1.inv() * R2).magnitude()) < 1.5
        assert np.linalg.norm(c.translation - t.translation) < 0.01
        assert abs(c.jaw[0] - t.jaw[0]) < 0.05
    assert np.median([np.abs(c.expression - t.expression).mean() for c, t in zip(r.controls, truth, strict=True)]) \
        < 0.08
    with torch.inference_mode():
        head = Head(model)
        deformed = [head.pose([Controls(expression=c.expression, jaw=c.jaw) for c in cs])[0].numpy()
                    for cs in (r.controls, truth)]
    assert np.percentile(np.linalg.norm(deformed[0] - deformed[1], axis=-1), 99) < 0.001


def test_a_frame_without_a_face_is_posed_between_its_neighbours(builtin_model):
    """A head turning at a steady 0.1 rad a frame (5 frames); frame 2's landmarks are all NaN (no face found) and
    one of frame 3's is infinite. Those are left out of the fit (error 0, not fitted), and frame 2, with no data
    of its own, starts from PnP's poses interpolated between frames 1 and 3 and is kept there by the smoothness:
    its yaw is 0.2 rad within 0.02 (1.1 degrees), its translation the others' within 5 mm."""
    ids = np.random.default_rng(0).choice(len(builtin_model.template), 40, replace=False)
    k = Intrinsics(500.0, 500.0, 128.0, 128.0)
    truth = [Controls(root=np.array([0.0, 0.1 * i, 0.0], np.float32),
                      translation=np.array([0.0, 0.0, -0.6], np.float32)) for i in range(5)]
    targets = synthetic_targets(builtin_model, truth, ids, k)
    targets[2] = np.nan
    targets[3, 7, 1] = np.inf
    r = fit(builtin_model, ids, targets, k, cfg=FitConfig(iterations=60, shape_components=0))
    assert not r.fitted[2].any() and not r.fitted[3, 7] and r.fitted.sum() == 5 * 40 - 40 - 1
    assert (r.error_px[~r.fitted] == 0).all() and np.isfinite(r.error_px).all()
    assert np.median(r.error_px[r.fitted]) < 1.0, np.median(r.error_px[r.fitted])
    yaw = Rotation.from_rotvec(r.controls[2].root).as_euler("YXZ")[0]
    assert abs(yaw - 0.2) < 0.02, yaw
    np.testing.assert_allclose(r.controls[2].translation, truth[2].translation, atol=0.005, rtol=0)


@pytest.mark.parametrize(("cut", "message"), [("all NaN", "no frame of 2 has 4 finite landmarks"),
                                              ("3 per frame", "no frame of 2 has 4 finite"),
                                              ("3 landmarks", "at least 4 landmarks"),
                                              ("no frames", "no frames"), ("wrong shape", "must be")])
def test_landmarks_that_cannot_be_fitted_are_a_fit_error(builtin_model, cut, message):
    """FitError (a ValueError: the CLI's one-line input error) says what is missing, never a NaN fit or an error
    from inside OpenCV or torch."""
    ids = np.arange(10)
    targets = np.full((2, 10, 2), 64.0, np.float32)
    if cut == "all NaN":
        targets[:] = np.nan
    elif cut == "3 per frame":
        targets[:, 3:] = np.nan
    elif cut == "3 landmarks":
        ids, targets = ids[:3], targets[:, :3]
    elif cut == "no frames":
        targets = targets[:0]
    else:
        targets = targets[..., :1]
    with pytest.raises(FitError, match=message):
        fit(builtin_model, ids, targets, Intrinsics(100.0, 100.0, 64.0, 64.0), cfg=FitConfig(iterations=2))
