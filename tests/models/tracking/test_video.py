"""The crop every tracked frame shares: what it keeps of the frame (each pixel the mean of its footprint, the
geometry exact at every scale), how large it is drawn, and the frames read again through it."""

from __future__ import annotations

import numpy as np
import pytest

from models.tracking.video import Crop, VideoError, cropped_frames, face_crop, sampled_frames
from render.video import write_video


def test_a_crop_shrunk_4x_averages_stripes_to_grey():
    """Columns alternating 0 and 255 (period 2 px), shrunk 4x: every output pixel covers 4 columns, two of each,
    so it is (2 * 0 + 2 * 255) / 4 = 127.5 everywhere. Bilinear sampling alone (what warpAffine does, INTER_AREA
    or not) lands on every 4th column, all of one colour, and gave 255 everywhere."""
    frame = np.zeros((1080, 1920, 3), np.uint8)
    frame[:, ::2] = 255
    out = Crop(400.0, 100.0, 880.0, 220).image(frame).astype(float)  # scale 220 / 880 = 1/4
    assert out.shape == (220, 220, 3)
    np.testing.assert_allclose(out, 127.5, atol=0.6)  # uint8 rounding


@pytest.mark.parametrize("scale", [1.6, 0.8, 0.5, 0.3, 0.25, 0.13])
def test_a_crop_puts_a_spot_where_its_points_say_and_keeps_its_light(scale):
    """A soft bright spot (a Gaussian 2.5 crop pixels wide, so that sampling it is not the question) in a dark
    frame, its centre at (1005.3, 505.8) in continuous pixel coordinates (as landmarks and intrinsics: pixel k
    spans k to k + 1, its centre at k + 0.5): in the crop its centroid is where `Crop.points` maps that centre,
    to 0.02 px (half a source pixel off would be 0.07 px at the smallest scale), and its light, summed, is the
    frame's times scale^2 (each crop pixel is scale^-2 source pixels), to 2% (uint8 rounding)."""
    ys, xs = np.mgrid[0:1080, 0:1920].astype(float) + 0.5  # pixel centres
    sigma = 2.5 / scale
    spot = 200 * np.exp(-((xs - 1005.3) ** 2 + (ys - 505.8) ** 2) / (2 * sigma**2))
    frame = np.repeat(spot.round().astype(np.uint8)[..., None], 3, -1)
    size = 128
    crop = Crop(1005.3 - 0.47 * size / scale, 505.8 - 0.53 * size / scale, size / scale, size)
    img = crop.image(frame)[..., 0].astype(float)
    cy, cx = np.mgrid[0:size, 0:size] + 0.5
    centroid = np.array([(img * cx).sum(), (img * cy).sum()]) / img.sum()
    np.testing.assert_allclose(centroid, crop.points(np.array([1005.3, 505.8])), atol=0.02)
    np.testing.assert_allclose(img.sum(), frame[..., 0].astype(float).sum() * scale**2, rtol=0.02)


def test_a_still_face_gets_the_margin_and_a_travelling_one_stays_inside():
    """A face 100 px across that never moves: side = 1.9 * 100 = 190 px (the reach, 2 (58 + 30) = 176, is less;
    58: the centre sits 8 px below the box's middle). Moved 120 px right in one of 11 frames, the median centre
    stays, and that box's far edge is 50 + 120 = 170 px from it: side = 2 (170 + 30) = 400 px, and the frame
    with the moved face is inside."""
    still = np.array([[0.0, 0.0], [100.0, 100.0]]) + [500.0, 300.0]
    crop = face_crop([still] * 11, 256, (1920, 1080))
    assert crop.side == pytest.approx(190.0)
    assert (crop.x0, crop.y0) == pytest.approx((550 - 95, 358 - 95))
    moved = still + [120.0, 0.0]
    crop = face_crop([still] * 10 + [moved], 256, (1920, 1080))
    assert crop.side == pytest.approx(400.0)
    pts = crop.points(moved)
    assert (pts >= 0).all() and (pts <= 256).all()
    # never larger than the frame, and inside it
    crop = face_crop([still, still + [1300.0, 0.0]] * 3, 256, (1920, 1080))
    assert crop.side == 1080 and 0 <= crop.x0 <= 1920 - 1080 and crop.y0 == 0


def test_frames_read_again_through_the_crop_are_the_sampled_frames_crops(tmp_path):
    """`cropped_frames` gives, for the frame numbers asked (in their order), what cropping the frame that
    `sampled_frames` decodes gives; a frame the file does not have is a clear error."""
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 255, (96, 160, 3), np.uint8) for _ in range(12)]
    video = tmp_path / "v.mp4"
    write_video(frames, video, fps=10)
    crop = Crop(30.0, 10.0, 80.0, 32)
    decoded = {i: rgb for i, _, rgb in sampled_frames(video, 5)}  # every other frame
    assert sorted(decoded) == [0, 2, 4, 6, 8, 10]
    got = cropped_frames(video, 5, crop, [8, 2, 4])
    for index, image in zip([8, 2, 4], got, strict=True):
        np.testing.assert_array_equal(image, crop.image(decoded[index]))
    with pytest.raises(VideoError, match=r"v\.mp4: frame 3 could not be decoded"):
        cropped_frames(video, 5, crop, [2, 3])
