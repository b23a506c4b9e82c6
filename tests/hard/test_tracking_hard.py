"""Hard cases for fitting the head model to landmarks (models/tracking/fit.py), swept by hypothesis: landmarks all
at one point, on one line, shrunk to a pixel or spread over 1e5 px, a face at the image's edge, half or wholly
outside it: the fit's outputs are finite, and a face moved across the image is still fitted. Input that cannot
be fitted (a NaN or infinite landmark, a frame without a face among faces, fewer landmarks than PnP needs, no
frames) must be refused with a clear error, not answered with NaN."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from models.head.controls import Controls
from models.head.head import Head
from models.tracking.fit import FitConfig, FitResult, Intrinsics, fit, project

pytestmark = pytest.mark.usefixtures("one_torch_thread")
SWEEP = settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                       HealthCheck.function_scoped_fixture])
K = Intrinsics(300.0, 300.0, 64.0, 64.0)  # a 128 x 128 image
FAST = FitConfig(iterations=6, shape_components=2)
N = 3  # frames


@pytest.fixture(scope="module")
def face(builtin_model):
    """The built-in head's 24 landmark vertices and their pixels (N,24,2) in 3 frames, the head turning, 0.6 m
    ahead of the camera (about 70 x 170 px)."""
    ids = np.random.default_rng(0).choice(len(builtin_model.template), 24, replace=False)
    return builtin_model, ids, face_pixels(builtin_model, ids, (0.0, 0.0))


def face_pixels(model, ids: np.ndarray, shift_px: tuple[float, float]) -> np.ndarray:
    """(N,24,2) the landmarks' pixels of the head moved sideways (0.6 m ahead) so that its centre's image moves by
    shift_px: a translation of shift * 0.6 m / 300 px."""
    move = np.array([shift_px[0], -shift_px[1], 0.0], np.float32) * 0.6 / K.fx
    controls = [Controls(root=np.array([0.0, 0.15 * i, 0.0], np.float32),
                         translation=np.array([0.0, 0.0, -0.6], np.float32) + move) for i in range(N)]
    with torch.inference_mode():
        verts = Head(model).pose(controls)[0]
    return project(verts[:, ids], K).numpy()


def run_fit(model, ids, targets, cfg: FitConfig = FAST) -> FitResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # what cv2 or numpy say on the way is not the point
        return fit(model, ids, targets.astype(np.float32), K, cfg=cfg)


def outputs_finite(r: FitResult) -> bool:
    parts = [r.shape, r.error_px] + [np.concatenate([c.root, c.translation, c.expression, c.jaw]) for c in r.controls]
    return all(np.isfinite(p).all() for p in parts)


def degenerate(targets: np.ndarray, kind: str, where: tuple[float, float], angle: float) -> np.ndarray:
    t = targets.copy()
    if kind == "one point":  # every landmark of every frame on one pixel (anywhere, in the image or not)
        t[:] = where
    elif kind == "collinear":  # every landmark on one line through `where`
        along = (t - t.mean((0, 1))) @ np.array([math.cos(angle), math.sin(angle)])
        t = np.asarray(where) + along[..., None] * np.array([math.cos(angle), math.sin(angle)])
    elif kind == "one pixel":  # the face shrunk to a thousandth of a pixel
        t = np.asarray(where) + 1e-3 * (t - t.mean((0, 1)))
    elif kind == "huge":  # spread over 1e5 pixels: a face far too close to be a head
        t = np.asarray(where) + 2000.0 * (t - t.mean((0, 1)))
    return t


@SWEEP
@given(kind=st.sampled_from(["one point", "collinear", "one pixel", "huge"]),
       where=st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)) | st.just((64.0, 64.0)),
       angle=st.sampled_from([0.0, math.pi / 2, 0.7]))
def test_degenerate_landmarks_give_finite_fits(face, kind, where, angle):
    model, ids, targets = face
    r = run_fit(model, ids, degenerate(targets, kind, where, angle))
    assert outputs_finite(r)


@settings(SWEEP, max_examples=4)
@given(shift=st.tuples(st.sampled_from([-64.0, -30.0, 0.0, 40.0, 64.0, 100.0, 200.0]),
                       st.sampled_from([-64.0, 0.0, 64.0, 150.0])))
def test_a_face_at_the_edge_or_outside_the_image_is_fitted(face, shift):
    """The head moved so that its centre's image lies on the image's edge (64 px from the centre), half outside or
    wholly outside it (a crop that lost the head): pixels beyond the image are landmarks like any other. PnP starts
    the fit on the true pose (1e-4 px), Adam's first steps move it by about its learning rate (3-5 px after 10
    steps) and 30 steps bring it back within 1.5 px at the median (0.5-0.9 px measured, as in the middle)."""
    model, ids, _ = face
    r = run_fit(model, ids, face_pixels(model, ids, shift), FitConfig(iterations=30, shape_components=2))
    assert outputs_finite(r)
    assert float(np.median(r.error_px)) < 1.5, np.median(r.error_px)


def finite_or_refused(model, ids, targets, frame: int) -> None:
    """Unusable input: either a ValueError that names the frame, or (the bad frame left out of the fit) every
    output finite."""
    try:
        r = run_fit(model, ids, targets)
    except ValueError as e:
        message = str(e)
    else:
        assert outputs_finite(r), "a NaN result instead of an error"
        return
    assert f"frame {frame}" in message, message


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_a_non_finite_landmark_is_refused_or_left_out(face, value):
    model, ids, targets = face
    t = targets.copy()
    t[1, 3, 0] = value  # frame 1, landmark 3, x
    finite_or_refused(model, ids, t, 1)


def test_a_frame_without_a_face_is_refused_or_left_out(face):
    model, ids, targets = face
    t = targets.copy()
    t[1] = np.nan  # the middle frame: the landmarker found no face
    finite_or_refused(model, ids, t, 1)


@pytest.mark.parametrize("cut", ["3 landmarks", "no frames"])
def test_too_little_to_fit_is_a_clear_error(face, cut):
    model, ids, targets = face
    if cut == "3 landmarks":
        ids, targets = ids[:3], targets[:, :3]
    else:
        targets = targets[:0]
    with pytest.raises(ValueError, match=r"landmark|frame"):
        run_fit(model, ids, targets)
