"""Camera matrices: hand-worked projections and the depth-buffer inversion."""

from __future__ import annotations

import numpy as np
import pytest

from render.camera import framing_camera, linear_depth_from_ndc, look_at, orbit_camera, perspective


def test_look_at_moves_eye_to_origin_and_looks_down_minus_z():
    view = look_at(np.array([0.0, 0.0, 2.0]), np.zeros(3))
    np.testing.assert_allclose(view @ [0, 0, 2, 1], [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(view @ [0, 0, 0, 1], [0, 0, -2, 1], atol=1e-12)


def test_look_at_with_up_along_a_view_along_z_falls_back_to_y():
    # f = (0, 0, 1); up = +z and the +z fallback are along it, so up = +y: s = f x y = (-1, 0, 0),
    # u = s x f = (0, 1, 0); rows s, u, -f.
    view = look_at(np.zeros(3), np.array([0.0, 0.0, 1.0]), up=(0.0, 0.0, 1.0))
    np.testing.assert_array_equal(view[:3, :3], [[-1, 0, 0], [0, 1, 0], [0, 0, -1]])
    # Looking straight down (f = (0, -1, 0)) with the default up +y: the +z fallback, as before.
    # s = f x z = (-1, 0, 0), u = s x f = (0, 0, 1).
    down = look_at(np.array([0.0, 1.0, 0.0]), np.zeros(3))
    np.testing.assert_array_equal(down[:3, :3], [[-1, 0, 0], [0, 0, 1], [0, 1, 0]])


def test_look_at_its_own_eye_is_refused():
    with pytest.raises(ValueError, match="eye and target coincide"):
        look_at(np.ones(3), np.ones(3))


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


def test_pinhole_projection_and_pixel_rays_agree_off_centre():
    """A camera with the principal point off the centre and fx != fy: each pixel centre's ray, projected back,
    lands on that pixel centre; a crop of a camera sees the same rays through the pixels the two share; a
    resized camera scales its intrinsics."""
    from render.camera import Camera
    from render.rays import camera_directions, pixel_rays

    view = look_at(np.array([0.3, 0.1, 1.5]), np.array([0.0, 0.05, 0.0]))
    cam = Camera.from_intrinsics(view, fx_px=70.0, fy_px=55.0, cx_px=21.3, cy_px=30.8, width_px=40, height_px=36)
    assert not cam.centred and cam.intrinsics == (70.0, 55.0, 21.3, 30.8)
    origin, dirs = pixel_rays(cam)
    pts = origin + dirs.reshape(-1, 3) * 0.9
    clip = (cam.projection @ cam.view @ np.c_[pts, np.ones(len(pts))].T).T
    u = (clip[:, 0] / clip[:, 3] + 1) * 0.5 * cam.width_px
    v = (1 - clip[:, 1] / clip[:, 3]) * 0.5 * cam.height_px
    j, i = np.meshgrid(np.arange(40) + 0.5, np.arange(36) + 0.5)
    np.testing.assert_allclose(u, j.ravel(), atol=1e-9)
    np.testing.assert_allclose(v, i.ravel(), atol=1e-9)
    # Hand-worked: the pixel whose centre is the principal point's column looks straight along x = 0.
    d = camera_directions(cam)
    assert d[0, 21, 0] == np.float64((21.5 - 21.3) / 70.0) and d[5, 0, 1] == -(5.5 - 30.8) / 55.0
    crop = cam.cropped(7, 4, 25, 20)
    _, crop_dirs = pixel_rays(crop)
    np.testing.assert_allclose(crop_dirs, dirs[4:24, 7:32], atol=1e-12)
    half = cam.resized(20, 18)
    np.testing.assert_allclose(half.intrinsics, (35.0, 27.5, 10.65, 15.4), atol=1e-12)
    # A centred camera keeps its centred projection.
    centred = Camera(view, 40.0, 32, 24)
    np.testing.assert_allclose(centred.projection, perspective(40.0, 32 / 24, 0.05, 5.0))
    np.testing.assert_allclose(centred.cropped(0, 0, 32, 24).projection, centred.projection, atol=1e-12)


def test_a_translated_head_stays_in_view(gl):
    """A translation control moves the head out of the neutral head's clipping range (+0.25 m: the near plane cut
    the face; -0.5 m: it vanished). The planes follow the posed head: the preview shows it whole either way."""
    from models.head.controls import Controls
    from models.head.head import Head
    from models.head.sources import load_head
    from render.camera import framing_camera
    from render.gl.preview import MeshFrame, PreviewRenderer

    model = load_head("builtin")
    cam = framing_camera(model.template, width_px=48, height_px=48)
    preview = PreviewRenderer(gl)
    covered = {}
    for dz in (0.0, 0.25, -0.5):
        verts = Head(model).pose([Controls(translation=np.array([0.0, 0.0, dz], np.float32))])[0][0].numpy()
        img = preview.render(MeshFrame(verts, model.triangles), cam, read_depth=True)
        covered[dz] = np.isfinite(preview.last_depth).mean()
        assert img.std() > 5
    # Nearer heads look bigger, farther smaller, and none is cut away.
    assert covered[0.25] > covered[0.0] > covered[-0.5] > 0.05, covered


def test_turntable_camera_fills_the_frame_at_every_yaw():
    """The built-in head's vertices, projected: inside the frame at every yaw, and at least 80% of its height at
    the front (framing_camera's bounding sphere gave about 55%)."""
    from models.head.sources import load_head
    from render.camera import turntable_camera

    v = load_head("builtin").template
    for yaw in (0.0, 45.0, 90.0, 180.0, 270.0):
        for pitch in (0.0, 10.0):
            cam = turntable_camera(v, yaw, pitch, width_px=100, height_px=100)
            p = np.c_[v, np.ones(len(v))] @ (cam.projection @ cam.view).T
            ndc = p[:, :2] / p[:, 3:]
            assert np.abs(ndc).max() <= 1.0, (yaw, pitch, np.abs(ndc).max())
            if yaw == 0.0 and pitch == 0.0:
                assert np.ptp(ndc[:, 1]) / 2 > 0.8, np.ptp(ndc[:, 1]) / 2
                sphere = framing_camera(v, 0.0, 0.0, fov_y_deg=18.0, width_px=100, height_px=100)
                q = np.c_[v, np.ones(len(v))] @ (sphere.projection @ sphere.view).T
                assert np.ptp(q[:, 1] / q[:, 3]) / 2 < np.ptp(ndc[:, 1]) / 2
