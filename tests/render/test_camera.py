"""Camera matrices: hand-worked projections and the depth-buffer inversion."""

from __future__ import annotations

import numpy as np

from render.camera import framing_camera, linear_depth_from_ndc, look_at, orbit_camera, perspective


def test_look_at_moves_eye_to_origin_and_looks_down_minus_z():
    view = look_at(np.array([0.0, 0.0, 2.0]), np.zeros(3))
    np.testing.assert_allclose(view @ [0, 0, 2, 1], [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(view @ [0, 0, 0, 1], [0, 0, -2, 1], atol=1e-12)


def test_perspective_hand_worked():
    # fov 90 degrees, aspect 1: a point at (1, 0, -1) lands on the right edge, x_ndc = 1.
    p = perspective(90.0, 1.0, 0.1, 10.0)
    clip = p @ [1.0, 0.0, -1.0, 1.0]
    assert abs(clip[0] / clip[3] - 1.0) < 1e-12
    # The near plane maps to depth -1, the far plane to +1.
    for z, ndc in ((-0.1, -1.0), (-10.0, 1.0)):
        c = p @ [0, 0, z, 1]
        assert abs(c[2] / c[3] - ndc) < 1e-12


def test_linear_depth_inverts_the_projection():
    p = perspective(40.0, 1.5, 0.05, 5.0)
    for d in (0.05, 0.3, 1.7, 5.0):
        c = p @ [0, 0, -d, 1]
        depth01 = 0.5 * (c[2] / c[3]) + 0.5
        assert abs(linear_depth_from_ndc(depth01, 0.05, 5.0) - d) < 1e-9


def test_orbit_yaw_moves_to_subjects_left():
    cam = orbit_camera(90.0, 0.0, 1.0, (0, 0, 0))
    np.testing.assert_allclose(cam.position, [1, 0, 0], atol=1e-12)


def test_framing_keeps_every_vertex_in_view():
    rng = np.random.default_rng(0)
    v = rng.normal(0, 0.1, (500, 3)) + [0.2, -0.1, 0.05]
    cam = framing_camera(v, yaw_deg=30, width_px=300, height_px=200)
    clip = (cam.projection @ cam.view @ np.c_[v, np.ones(len(v))].T).T
    ndc = clip[:, :3] / clip[:, 3:]
    assert np.abs(ndc).max() < 1.0
