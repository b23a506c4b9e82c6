"""The built-in head: regenerated bit for bit, and built like a head (features where a face has them,
joints that open the jaw and turn the eyes, expressions that do what their names say)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from models.head.builtin import EXPRESSIONS, SHAPES, SHIPPED_PATH, build_builtin_arrays
from models.head.controls import Controls
from models.head.head import Head


def test_regenerates_what_ships():
    built = build_builtin_arrays()
    with np.load(SHIPPED_PATH, allow_pickle=False) as shipped:
        assert sorted(shipped.files) == sorted(built)
        for key, value in built.items():
            np.testing.assert_array_equal(shipped[key], value, err_msg=key)


def test_inventory(builtin_model):
    m = builtin_model
    assert m.joint_names == ("root", "neck", "jaw", "eye_l", "eye_r")
    assert m.num_expression >= 10 and len(set(m.expr_names)) == m.num_expression == len(EXPRESSIONS)
    assert m.num_shape >= 10 and len(SHAPES) == m.num_shape
    assert m.landmarks.count == 68
    assert m.uv is not None and m.uv.min() >= 0 and m.uv.max() <= 1
    assert m.triangles_uv.shape == m.triangles.shape
    np.testing.assert_allclose(m.weights.sum(1), 1.0, atol=1e-6)
    np.testing.assert_allclose(m.J_regressor.sum(1), 1.0, atol=1e-6)


def _signed_volume(v, f):
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def test_surface_faces_outward(builtin_model):
    """Triangles wind counter-clockwise seen from outside: the enclosed volume is positive and about
    that of a head (skin open at the neck's base, eyeballs closed)."""
    m = builtin_model
    vol = _signed_volume(m.template.astype(np.float64), m.triangles)
    assert 3e-3 < vol < 8e-3  # m^3: a head and neck are about 4-6 litres


def test_face_features_where_a_face_has_them(builtin_model):
    m = builtin_model
    lm = m.template[m.landmarks.vertex_ids]
    nose_tip, chin, brow_l, eye_l_outer = lm[30], lm[8], lm[24], lm[45]
    # The nose tip is the front-most point of the skin; it stands well proud of the cheeks.
    assert np.argmax(m.template[:, 2]) == m.landmarks.vertex_ids[30] or nose_tip[2] >= m.template[:, 2].max() - 1e-3
    cheek = m.template[np.argmin(np.sum((m.template[:, :2] - [0.045, -0.005]) ** 2, 1)
                                 + 1e3 * (m.template[:, 2] < 0))]
    assert nose_tip[2] - cheek[2] > 0.02
    # Top to bottom: brows above eyes above nose tip above mouth above chin.
    mouth = lm[51]
    assert brow_l[1] > eye_l_outer[1] > nose_tip[1] > mouth[1] > chin[1]
    # Subject's left on +x: landmarks 42-47 (left eye in the iBUG layout) have x > 0; each eye's first
    # point is its corner nearest the image's left (outer for the right eye, inner for the left).
    assert (lm[42:48, 0] > 0).all() and (lm[36:42, 0] < 0).all()
    assert lm[36, 0] < lm[39, 0] and lm[42, 0] < lm[45, 0] and lm[48, 0] < lm[54, 0] and lm[0, 0] < lm[16, 0]
    assert abs(lm[39, 0]) < abs(lm[36, 0]) and abs(lm[42, 0]) < abs(lm[45, 0])  # inner corners nearer the nose
    # Ears: skin stands out sideways beyond the head at ear height, behind the face.
    ear_zone = (np.abs(m.template[:, 1] - 0.012) < 0.02) & (np.abs(m.template[:, 2] + 0.014) < 0.012)
    assert np.abs(m.template[ear_zone, 0]).max() > 0.085


def test_eyeballs_sit_on_their_joints(builtin_model):
    m = builtin_model
    joints = m.J_regressor @ m.template
    eye_l, eye_r = joints[3], joints[4]
    assert eye_l[0] > 0.02 and eye_r[0] < -0.02
    on_l = m.weights[:, 3] == 1
    np.testing.assert_allclose(np.linalg.norm(m.template[on_l] - eye_l, axis=1), 0.0125, atol=1e-6)


def test_jaw_opens_the_mouth(builtin_model):
    head = Head(builtin_model)
    lm0 = head.pose(Controls())[2][0]
    lm1 = head.pose(Controls(jaw=np.array([0.3, 0.0, 0.0])))[2][0]
    gap0 = lm0[62, 1] - lm0[66, 1]  # inner lips: upper middle minus lower middle
    gap1 = lm1[62, 1] - lm1[66, 1]
    assert gap0 < 0.002 and gap1 > 0.015
    assert lm0[8, 1] - lm1[8, 1] > 0.012  # the chin drops
    torch.testing.assert_close(lm1[17:48], lm0[17:48])  # brows, nose and eyes stay


@pytest.mark.parametrize(("name", "upper", "lower", "open_mm"), [("blink_L", 44, 46, 5.0), ("blink_R", 37, 41, 5.0)])
def test_blink_closes_the_eye(builtin_model, name, upper, lower, open_mm):
    head = Head(builtin_model)
    lm0 = head.pose(Controls())[2][0]
    lm1 = head.pose(Controls().with_expression(builtin_model, {name: 1.0}))[2][0]
    assert (lm0[upper, 1] - lm0[lower, 1]) * 1e3 > open_mm
    assert abs(lm1[upper, 1] - lm1[lower, 1]) * 1e3 < 1.0


def test_smile_lifts_the_mouth_corners(builtin_model):
    head = Head(builtin_model)
    lm0 = head.pose(Controls())[2][0]
    lm1 = head.pose(Controls().with_expression(builtin_model, {"smile_L": 1.0, "smile_R": 1.0}))[2][0]
    assert lm1[48, 1] - lm0[48, 1] > 0.003 and lm1[54, 1] - lm0[54, 1] > 0.003
    assert lm1[54, 0] > lm0[54, 0] and lm1[48, 0] < lm0[48, 0]  # and widens it


def test_gaze_turns_the_eyeball(builtin_model):
    head = Head(builtin_model, dtype=torch.float64)
    v0 = head.pose(Controls())[0][0]
    v1 = head.pose(Controls(gaze_left=np.array([0.0, 0.4, 0.0])))[0][0]
    on_l = torch.as_tensor(builtin_model.weights[:, 3] == 1)
    assert (v1[on_l] - v0[on_l]).norm(dim=1).max() > 0.004
    torch.testing.assert_close(v1[~on_l], v0[~on_l])
