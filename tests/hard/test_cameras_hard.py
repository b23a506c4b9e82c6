"""Hard cases for cameras and rays (render/camera.py, render/rays.py), swept by hypothesis: focal lengths from 1e-3
to 1e6 px, fx and fy apart, the principal point up to 1e6 px outside the image, 1x1, 4096x1 and 1x4096 images;
cameras at the origin, inside the head, far away, looking straight up or down. Rays are finite and unit, a pixel
centre's ray projects back onto that pixel, a crop's rays are its camera's, look_at gives a rotation that looks at
its target; a camera at its own target, or an up along the view with no other up to fall back on, must be refused
rather than give NaN."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from render.camera import Camera, clipping_around, look_at, orbit_camera
from render.rays import camera_directions, image_rays, pixel_directions, pixel_rays

SWEEP = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
focal = st.floats(-3, 6).map(lambda e: 10.0 ** e)  # 1e-3 to 1e6 px
size = st.sampled_from([(1, 1), (4096, 1), (1, 4096), (3, 2), (64, 48)])
offset = st.floats(-1e6, 1e6, allow_nan=False) | st.sampled_from([0.0, 0.5])
coord = st.floats(-10.0, 10.0, allow_nan=False)
point = st.tuples(coord, coord, coord).map(np.array) | st.just(np.zeros(3))  # the origin: a camera there
direction = st.tuples(coord, coord, coord).filter(lambda v: np.linalg.norm(v) > 1e-3).map(
    lambda v: np.asarray(v) / np.linalg.norm(v)) | st.sampled_from([np.array(v, float) for v in
                                                                    ((0, 1, 0), (0, -1, 0), (0, 0, -1), (1, 0, 0))])


@st.composite
def cameras(draw) -> Camera:
    """A camera with extreme intrinsics (or the centred form, by field of view) at `point` looking along
    `direction` (straight up and down among them)."""
    w, h = draw(size)
    eye, ahead = draw(point), draw(direction)
    view = look_at(eye, eye + ahead)
    if draw(st.booleans()):  # centred, square pixels: the form every camera but a crop's has
        fy = draw(focal)
        return Camera(view, math.degrees(2 * math.atan(0.5 * h / fy)), w, h)
    fx, fy = draw(focal), draw(focal)
    return Camera.from_intrinsics(view, fx, fy, w / 2 + draw(offset), h / 2 + draw(offset), w, h)


@SWEEP
@given(cam=cameras())
def test_rays_are_finite_and_unit(cam):
    origin, d = pixel_rays(cam)
    assert np.isfinite(origin).all() and np.isfinite(d).all() and d.shape == (cam.height_px, cam.width_px, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12, rtol=0)
    o32, d32 = image_rays(cam)  # what training and rendering take: float32
    assert np.isfinite(d32.numpy()).all() and np.isfinite(o32.numpy()).all()
    np.testing.assert_allclose(d32.norm(dim=-1).numpy(), 1.0, atol=1e-6, rtol=0)


@SWEEP
@given(cam=cameras(), pick=st.lists(st.integers(0, 4096 * 4096), min_size=1, max_size=8))
def test_a_pixels_ray_is_the_images(cam, pick):
    """pixel_directions (a few pixels of a following crop's frame) is camera_directions normalised, pixel for
    pixel, whatever the intrinsics (1e-12)."""
    pixels = np.asarray(pick) % (cam.width_px * cam.height_px)
    table = camera_directions(cam).reshape(-1, 3)[pixels]
    table /= np.linalg.norm(table, axis=-1, keepdims=True)
    np.testing.assert_allclose(pixel_directions(cam.intrinsics, cam.width_px, pixels), table, atol=1e-12, rtol=0)


@SWEEP
@given(cam=cameras(), distance=st.sampled_from([1e-3, 0.3, 1.0, 100.0]))
def test_a_pixel_centres_ray_projects_back_onto_it(cam, distance):
    """A point on each pixel centre's ray, through the camera's view and GL projection (the clip matrix, the w
    divide, NDC to pixels), lands on that pixel's centre. Within float64's reach: a ray can lie within 1e-9 of 90
    degrees off the axis (f = 1e-3 px, the principal point 1e6 px away), or f be 1e6 px, and the point's camera
    coordinates, taken from world ones as large as the eye's distance from the origin, keep few of their digits:
    the pixel comes back within 1e-9 px plus 1e-13 of (focal lengths + offset from the principal point) times
    the digits lost (the eye's distance against the point's, times the ray's length in units of its depth)."""
    origin, d = pixel_rays(cam)
    points = origin + distance * d.reshape(-1, 3)
    clip = (cam.projection @ cam.view @ np.c_[points, np.ones(len(points))].T).T
    assert (clip[:, 3] > 0).all()  # in front of the camera
    u = (clip[:, 0] / clip[:, 3] + 1) / 2 * cam.width_px
    v = (1 - clip[:, 1] / clip[:, 3]) / 2 * cam.height_px
    j, i = (a.ravel() for a in np.meshgrid(np.arange(cam.width_px) + 0.5, np.arange(cam.height_px) + 0.5))
    fx, fy, cx, cy = cam.intrinsics
    lost = (1 + np.linalg.norm(origin) / distance) * np.linalg.norm(camera_directions(cam).reshape(-1, 3), axis=-1)
    tol = 1e-9 * (1 + abs(cx) + abs(cy)) + 1e-13 * (fx + fy + np.abs(j - cx) + np.abs(i - cy)) * lost
    assert (np.abs(u - j) <= tol).all(), np.abs(u - j).max()
    assert (np.abs(v - i) <= tol).all(), np.abs(v - i).max()


@SWEEP
@given(cam=cameras(), left=st.integers(-5, 5), top=st.integers(-5, 5))
def test_a_crops_rays_are_its_cameras(cam, left, top):
    """A crop (its window may reach past the image: a following crop near the edge) sees along the same rays as
    the camera through the pixels they share (1e-12)."""
    w, h = min(cam.width_px, 8), min(cam.height_px, 8)
    _, full = pixel_rays(cam)
    _, crop = pixel_rays(cam.cropped(left, top, w, h))
    assert np.isfinite(crop).all()
    r0, r1 = max(0, top), min(cam.height_px, top + h)
    c0, c1 = max(0, left), min(cam.width_px, left + w)
    if r0 < r1 and c0 < c1:  # they share some pixels
        np.testing.assert_allclose(crop[r0 - top: r1 - top, c0 - left: c1 - left], full[r0:r1, c0:c1], atol=1e-12,
                                   rtol=0)


@SWEEP
@given(eye=point, ahead=direction, far=st.sampled_from([1e-6, 1.0, 1e6]))
def test_look_at_is_a_rotation_that_looks_at_its_target(eye, ahead, far):
    """From the origin, from far off, with the target a micrometre or a thousand kilometres away, looking straight
    up or down (up = +y along the view: another up is taken): the view's rotation is orthonormal with det 1, the
    target lies straight ahead at its distance, and the image's up leans towards +y where the view allows."""
    target = eye + far * ahead
    v = look_at(eye, target)
    R = v[:3, :3]
    assert np.isfinite(v).all()
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12, rtol=0)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    ahead_cam = R @ (target - eye)  # the target in camera axes, relative to the eye
    np.testing.assert_allclose(ahead_cam, [0.0, 0.0, -np.linalg.norm(target - eye)], atol=1e-9 * (1 + far), rtol=0)
    np.testing.assert_allclose(v @ np.r_[eye, 1.0], [0.0, 0.0, 0.0, 1.0], atol=1e-12 * (1 + np.abs(eye).max()))
    assert R[1] @ np.array([0.0, 1.0, 0.0]) >= -1e-12  # the image's +y is never upside down


@pytest.mark.parametrize("pitch_deg", [-90.0, -89.9999, 0.0, 89.9999, 90.0])
def test_an_orbit_camera_straight_above_or_below_looks_at_the_target(pitch_deg):
    cam = orbit_camera(0.0, pitch_deg, 0.6, (0.0, 0.1, 0.0), width_px=1, height_px=1)
    origin, d = pixel_rays(cam)
    assert np.isfinite(d).all()
    np.testing.assert_allclose(origin + 0.6 * d[0, 0], [0.0, 0.1, 0.0], atol=1e-9, rtol=0)


@SWEEP
@given(eye=st.tuples(*[st.floats(-0.05, 0.05)] * 3).map(np.array), ahead=direction,
       points=st.lists(st.tuples(*[st.floats(-0.1, 0.1)] * 3), min_size=1, max_size=20),
       far=st.sampled_from([None, 1e30, np.inf, np.nan]))
def test_near_and_far_around_a_head_with_the_camera_inside(eye, ahead, points, far):
    """A camera inside the head (its points all round it, some behind), a point at 1e30 m, inf or NaN among them:
    near and far stay finite (non-finite depths are left out), 1e-3 <= near < far; points all behind the camera
    leave it as it was."""
    cam = Camera(look_at(eye, eye + ahead), 30.0, 8, 8, near_m=0.5, far_m=0.6)
    p = np.asarray(points, np.float64)
    with warnings.catch_warnings(), np.errstate(invalid="ignore"):  # inf * 0, inf - inf: a point at inf
        warnings.simplefilter("ignore", RuntimeWarning)
        if far is not None:
            p = np.vstack([p, eye + far * ahead])
        c = clipping_around(cam, p)
        depth = -(p @ cam.view[:3, :3].T + cam.view[:3, 3])[:, 2]
    assert math.isfinite(c.near_m) and math.isfinite(c.far_m)
    assert 1e-3 <= c.near_m < c.far_m
    if not (depth[np.isfinite(depth)] > 0).any():
        assert c is cam


@pytest.mark.parametrize("eye", [(0.0, 0.0, 0.0), (0.1, -0.2, 0.6)])
def test_a_camera_at_its_own_target_is_refused(eye):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # a NaN made on the way is not a refusal
        with pytest.raises(ValueError, match="target"):
            look_at(np.array(eye), np.array(eye))


@pytest.mark.parametrize("ahead", [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0)])
def test_an_up_along_a_view_along_z_still_gives_a_rotation(ahead):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        v = look_at(np.zeros(3), np.array(ahead), up=(0.0, 0.0, 1.0))
    assert np.isfinite(v).all()
    np.testing.assert_allclose(v[:3, :3] @ v[:3, :3].T, np.eye(3), atol=1e-12, rtol=0)
