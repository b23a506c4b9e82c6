"""A face as the landmarker gives it, carried onto the built-in head's channels as it comes: relative to the first
face (the neutral), hand-worked; then the same faces smoothed."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from models.tracking.blendshapes import JAW_OPEN_RAD
from models.tracking.landmarker import Face
from models.tracking.live import LiveRetarget, LiveSmoothing, controls_from_face

LIMITS = {"expression": (-1.0, 1.5), "jaw.open": (-5.0, 30.0), "gaze": (-30.0, 30.0)}
NO_SMOOTHING = LiveSmoothing(min_cutoff_hz=1e12)  # alpha = 1 / (1 + tau/dt) = 1 to 1e-10: every sample passes


def face(jaw_open: float = 0.0, smile_left: float = 0.0, yaw_deg: float = 0.0, pitch_deg: float = 0.0) -> Face:
    pose = np.eye(4, dtype=np.float32)
    pose[:3, :3] = Rotation.from_euler("YXZ", [yaw_deg, pitch_deg, 0.0], degrees=True).as_matrix()
    pose[:3, 3] = [0.0, 0.0, -45.0]  # 45 cm in front of the camera: not carried
    return Face(np.zeros((478, 2), np.float32), np.zeros(478, np.float32),
                {"jawOpen": jaw_open, "mouthSmileLeft": smile_left}, pose)


def test_a_face_in_the_head_models_terms(builtin_model):
    c = controls_from_face(face(jaw_open=0.5, smile_left=0.4, yaw_deg=10.0), builtin_model)
    assert c.jaw[0] == pytest.approx(0.5 * JAW_OPEN_RAD)
    assert c.expression[builtin_model.expression_index("smile_L")] == pytest.approx(0.4)
    np.testing.assert_allclose(c.root, [0.0, math.radians(10.0), 0.0], atol=1e-6)  # yaw: about +y
    np.testing.assert_array_equal(c.translation, 0.0)


def test_motion_is_taken_from_the_first_face(builtin_model):
    live = LiveRetarget(builtin_model, LIMITS, NO_SMOOTHING)
    # The neutral face: jaw a little open (0.1), head pitched 5 degrees: the avatar's rest.
    rest = live(face(jaw_open=0.1, pitch_deg=5.0), 0.0)
    assert all(v == pytest.approx(0.0, abs=1e-4) for v in rest.values()), rest
    # Jaw 0.5: 0.35 rad x (0.5 - 0.1) = 0.14 rad = 8.021 degrees; smile 0.4 - 0; the head turned 12 degrees from
    # the neutral face's pose (yaw then the same pitch): head.yaw 12, pitch 0.
    moved = live(face(jaw_open=0.5, smile_left=0.4, yaw_deg=12.0, pitch_deg=5.0), 1 / 30)
    assert moved["jaw.open"] == pytest.approx(math.degrees(0.14), abs=1e-3)
    assert moved["expression.smile_L"] == pytest.approx(0.4, abs=1e-6)
    assert moved["head.yaw"] == pytest.approx(12.0, abs=1e-3) and moved["head.pitch"] == pytest.approx(0.0, abs=1e-3)
    live.set_neutral()  # the next face is the new rest
    assert live(face(jaw_open=0.5, smile_left=0.4, yaw_deg=12.0, pitch_deg=5.0), 2 / 30)["jaw.open"] == \
        pytest.approx(0.0, abs=1e-6)


def test_smoothing_lags_a_step_a_little_and_holds_a_still_face(builtin_model):
    live = LiveRetarget(builtin_model, LIMITS)  # 1.5 Hz at rest, beta 0.2 a degree/s
    live(face(), 0.0)
    full = math.degrees(0.6 * JAW_OPEN_RAD)  # 12.03 degrees
    jaw = [live(face(jaw_open=0.6), k / 30)["jaw.open"] for k in range(1, 16)]
    # The step's speed raises the cutoff: about three quarters of the way in the first frame (8.97 of 12.03
    # degrees), nearly all of it 100 ms after the step, where the cutoff at rest alone (alpha 0.24 at 30 fps) would
    # have come 56% of the way (1 - 0.76^3).
    assert 0.6 * full < jaw[0] < 0.9 * full and jaw[2] > 0.95 * full, jaw
    assert jaw[-1] == pytest.approx(full, rel=1e-3)
    assert all(b >= a for a, b in itertools.pairwise(jaw))  # no overshoot on the way
    still = [live(face(jaw_open=0.6 + 0.02 * (-1) ** k), 0.5 + k / 30)["jaw.open"] for k in range(30)]
    assert np.ptp(still[10:]) < 0.25 * math.degrees(0.04 * JAW_OPEN_RAD)  # jitter of +-0.02 mostly removed
