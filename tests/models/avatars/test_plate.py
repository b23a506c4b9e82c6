"""A tracked video's background plate: estimated from the frames where the person leaves the room free,
composited behind the avatar along the capture camera's rays only, and saved with the avatar."""

from __future__ import annotations

import json

import numpy as np
import pytest

from models.avatars.checkpoint import save_checkpoint
from models.avatars.registry import load_avatar
from models.avatars.rendering import render_image
from models.head.controls import Controls
from models.tracking.masks import background_plate
from render.camera import Camera, framing_camera
from render.gl.raster import Rasterizer
from tests.conftest import CODYNERF_DEMO


def test_plate_is_the_room_where_the_person_leaves_it_free():
    """A 20x24 room of random colours; a 6x6 'person' walks along row 4..10 from x = 0 to x = 14, over 8 frames.
    Pixels it covers in fewer than half the frames get the room exactly (the median of identical values);
    the pixels it covers in more than half (none here but a band) are inpainted, and their share reported."""
    rng = np.random.default_rng(0)
    room = rng.integers(0, 256, (20, 24, 3), dtype=np.uint8)
    frames, masks = [], []
    for k in range(8):
        x0 = 2 * k
        frame, mask = room.copy(), np.zeros((20, 24), np.float32)
        frame[4:10, x0:x0 + 6] = 255 - room[4:10, x0:x0 + 6]  # the person's colours differ from the room
        mask[4:10, x0:x0 + 6] = 1.0
        frames.append(frame)
        masks.append(mask)
    plate, inpainted = background_plate(frames, masks, grow_px=0, min_share=0.5)
    covered = np.stack(masks).sum(0)  # frames in which each pixel is behind the person
    free_enough = (8 - covered) >= 4
    np.testing.assert_array_equal(plate[free_enough], room[free_enough])
    # Column x is covered in the frames k with 2k <= x < 2k + 6: three frames for x in 4..13, so every pixel is
    # free in at least five of eight; nothing is inpainted.
    assert inpainted == 0.0 and free_enough.all()
    # A person that stands still over half the frames leaves those pixels to inpainting: 36 of 480 pixels.
    plate2, inpainted2 = background_plate(frames[:1] * 5 + frames[5:], masks[:1] * 5 + masks[5:], grow_px=0,
                                          min_share=0.5)
    assert inpainted2 == pytest.approx(36 / 480)
    assert 60 < plate2[4:10, 0:6].mean() < 200  # filled from the room around (random colours, mean 127.5), not 0


def test_windows_of_a_following_crop_make_one_plate_of_the_room():
    """A following crop's frames each see a 10x12 window of a 20x30 room (offsets along a diagonal), a person at the
    window's centre: the plate is the room wherever the windows that hold a pixel saw it free in half of them and in
    3, or in all where fewer than 3 hold it (the canvas's edges); the corners no window held are inpainted. Every
    window at offset zero on a plate of its own size is the fixed crop's plate, bit for bit."""
    rng = np.random.default_rng(3)
    room = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    offsets = np.array([[3 * k, k] for k in range(7)])  # x 0..18, y 0..6
    frames, masks = [], []
    for ox, oy in offsets:
        frame, mask = room[oy:oy + 10, ox:ox + 12].copy(), np.zeros((10, 12), np.float32)
        frame[3:7, 4:8] = 255 - frame[3:7, 4:8]
        mask[3:7, 4:8] = 1.0
        frames.append(frame)
        masks.append(mask)
    plate, inpainted = background_plate(frames, masks, grow_px=0, min_share=0.5, offsets=offsets, canvas_wh=(30, 20))
    assert plate.shape == (20, 30, 3)
    seen = np.zeros((20, 30), int)
    free = np.zeros((20, 30), int)
    for (ox, oy), m in zip(offsets, masks, strict=True):
        seen[oy:oy + 10, ox:ox + 12] += 1
        free[oy:oy + 10, ox:ox + 12] += m < 0.5
    good = (seen > 0) & (free >= np.maximum(np.minimum(3, seen), np.ceil(0.5 * seen)))
    np.testing.assert_array_equal(plate[good], room[good])
    assert good.sum() > 0.4 * good.size and inpainted == pytest.approx(1 - good.mean())
    fixed, share = background_plate(frames, masks, grow_px=1, min_share=0.2)
    again, share_again = background_plate(frames, masks, grow_px=1, min_share=0.2, offsets=np.zeros((7, 2), int),
                                          canvas_wh=(12, 10))
    np.testing.assert_array_equal(fixed, again)
    assert share == share_again


@pytest.mark.gl
def test_a_frames_window_of_the_plate_composites_behind_it(gl):
    """A plate wider than the frames (a following crop's canvas): a frame's camera, the plate's cut at (x0, y0),
    composites over exactly that window of it (at its own size, and scaled to half); a window reaching past the
    plate, or a principal point off the whole pixels, has none."""
    avatar, _ = load_avatar(CODYNERF_DEMO)
    canvas = framing_camera(avatar.head_model.template, 0.0, 0.0, fov_y_deg=30.0, width_px=60, height_px=40)
    fx, fy, cx, cy = canvas.intrinsics
    plate = np.random.default_rng(4).random((40, 60, 3)).astype(np.float32)
    avatar.plate.note(plate, canvas)
    window = canvas.cropped(14, 6, 24, 20)
    np.testing.assert_array_equal(avatar.plate.for_camera(window).numpy(), plate[6:26, 14:38].reshape(-1, 3))
    r = Rasterizer(gl)
    out = render_image(avatar, window, Controls(), rasterizer=r)
    r.release()
    assert out["opacity"][0, 0] < 1e-3  # no head in the window's corner: the plate's pixel (14, 6) shows
    np.testing.assert_allclose(out["rgb"][0, 0], plate[6, 14], atol=1e-3)
    half = window.resized(12, 10)
    np.testing.assert_allclose(avatar.plate.for_camera(half).numpy().reshape(10, 12, 3)[0, 0],
                               plate[6:8, 14:16].mean((0, 1)),
                               atol=1e-6)
    past = canvas.cropped(40, 0, 24, 20)  # x 40..64 of a 60-wide plate
    between = Camera.from_intrinsics(canvas.view, fx, fy, cx - 14.5, cy - 6, 24, 20, near_m=0.05, far_m=10.0)
    assert avatar.plate.for_camera(past) is None and avatar.plate.for_camera(between) is None


@pytest.mark.gl
def test_plate_composites_behind_the_capture_camera_only(gl):
    """The same avatar with and without a plate: along the plate's camera, every pixel differs by exactly the light
    that passes the avatar times (plate - background colour); any other camera sees the background colour."""
    avatar, _ = load_avatar(CODYNERF_DEMO)
    cam = framing_camera(avatar.head_model.template, 10.0, 0.0, fov_y_deg=18.0, width_px=40, height_px=36)
    r = Rasterizer(gl)
    controls = Controls(jaw=np.array([0.15, 0.0, 0.0], np.float32))
    bare = render_image(avatar, cam, controls, rasterizer=r)
    plate = np.random.default_rng(1).random((36, 40, 3)).astype(np.float32)
    avatar.plate.note(plate, cam)
    with_plate = render_image(avatar, cam, controls, rasterizer=r)
    bg = avatar.background.numpy()
    expected = bare["rgb"] + (1 - bare["opacity"])[..., None] * (plate - bg)
    np.testing.assert_allclose(with_plate["rgb"], expected, atol=2e-5)
    assert (bare["opacity"] < 1e-3).mean() > 0.3  # much of the frame is the room
    np.testing.assert_array_equal(with_plate["opacity"], bare["opacity"])
    half = render_image(avatar, cam.resized(20, 18), controls, rasterizer=r)  # the same camera at half the size
    np.testing.assert_allclose(half["rgb"][0, 0], plate[:2, :2].mean((0, 1)), atol=1e-5)  # area-averaged
    other = render_image(avatar, framing_camera(avatar.head_model.template, 40.0, 0.0, fov_y_deg=18.0, width_px=40,
                                                height_px=36), controls, rasterizer=r)  # another view: no plate
    np.testing.assert_allclose(other["rgb"][0, 0], bg, atol=1e-6)
    r.release()


def test_plate_is_saved_with_the_avatar(tmp_path):
    avatar, meta = load_avatar(CODYNERF_DEMO)
    cam = framing_camera(avatar.head_model.template, 0.0, 0.0, width_px=12, height_px=10)
    plate = np.random.default_rng(2).random((10, 12, 3)).astype(np.float32)
    avatar.plate.note(plate, cam)
    save_checkpoint(tmp_path / "av", json.loads(json.dumps(meta)), avatar.state_dict(), 1)
    again, _ = load_avatar(tmp_path / "av")
    np.testing.assert_array_equal(again.plate.image.numpy(), plate)
    assert again.plate.for_camera(cam) is not None and again.plate.for_camera(cam.resized(24, 20)).shape == (480, 3)
    other = framing_camera(again.head_model.template, 5.0, 0.0, width_px=12, height_px=10)
    assert again.plate.for_camera(other) is None
    # An avatar without a plate (the shipped demo) still loads, and has none.
    assert load_avatar(CODYNERF_DEMO)[0].plate.for_camera(cam) is None
