"""Foreground masks: GrabCut seeded by the face, one by one or in worker processes, the same masks."""

from __future__ import annotations

import warnings

import numpy as np

from models.tracking.masks import (
    STILL_ROOM_LEVELS,
    background_plate,
    foreground_mask,
    foreground_masks,
    masked_median,
    room_residual,
)


def portrait(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 96 px frame: a noisy blue-grey room and a skin-coloured head (an ellipse) over a dark torso, and 40 points
    round the face as its landmarks."""
    rng = np.random.default_rng(seed)
    h = w = 96
    yy, xx = np.mgrid[:h, :w]
    img = (np.array([90, 110, 130]) + rng.normal(0, 8, (h, w, 3))).clip(0, 255)
    cx, cy = 48 + rng.integers(-4, 5), 40
    head = ((xx - cx) / 18.0) ** 2 + ((yy - cy) / 24.0) ** 2 < 1
    img[head] = np.array([200, 150, 120]) + rng.normal(0, 6, (head.sum(), 3))
    img[(yy > 66) & (np.abs(xx - cx) < 30 + (yy - 66))] = [40, 40, 50]
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    landmarks = np.stack([cx + 14 * np.cos(t), cy + 4 + 18 * np.sin(t)], 1)
    return img.astype(np.uint8), landmarks


def test_masks_in_workers_are_the_masks_one_by_one():
    """Two worker processes give every frame the mask a call of its own gives, in order (GrabCut's generator is
    seeded per frame, so a mask does not depend on the frames cut before it), and the mask is the head: most of the
    ellipse, little of the room above the shoulders."""
    frames = [portrait(k) for k in range(6)]
    alone = [foreground_mask(img, lm) for img, lm in reversed(frames)][::-1]
    pooled = foreground_masks([f[0] for f in frames], [f[1] for f in frames], workers=2)
    seen = []
    one_by_one = foreground_masks([f[0] for f in frames], [f[1] for f in frames], workers=1,
                                  progress=lambda done, total: seen.append((done, total)))
    for a, b, c in zip(alone, pooled, one_by_one, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
    assert seen == [(k, 6) for k in range(1, 7)]
    lm = frames[0][1]
    yy, xx = np.mgrid[:96, :96]
    cx = lm[:, 0].mean()
    head = ((xx - cx) / 18.0) ** 2 + ((yy - 40) / 24.0) ** 2 < 0.8
    corner = (yy < 20) & ((xx < 15) | (xx > 80))
    assert alone[0][head].mean() > 0.95 and alone[0][corner].mean() < 0.05


def test_a_room_that_moves_is_told_from_a_still_one():
    """A textured room behind a person (a disc that moves about): seen by a still camera with a level of noise, its
    frames differ from their plate by about that noise; panned 3 px a frame, by far more than STILL_ROOM_LEVELS."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(0)
    room = np.stack([gaussian_filter(rng.random((96, 160)), 2) for _ in range(3)], -1)
    room = ((room - room.min()) / np.ptp(room) * 255).astype(np.float64)
    yy, xx = np.mgrid[:64, :64]

    def frames(pan_px: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
        images, masks = [], []
        for k in range(12):
            image = room[16:80, 8 + pan_px * k: 72 + pan_px * k] + rng.normal(0, 1.0, (64, 64, 3))
            person = ((xx - 28 - k) ** 2 + (yy - 36) ** 2 < 14 ** 2).astype(np.float32)
            image[person > 0] = 200.0
            images.append(image.clip(0, 255).astype(np.uint8))
            masks.append(person)
        return images, masks

    for pan, still in ((0, True), (3, False)):
        images, masks = frames(pan)
        plate, _ = background_plate(images, masks, grow_px=1)
        level = room_residual(images, masks, plate, grow_px=2)
        assert (level <= STILL_ROOM_LEVELS) == still, (pan, level)
        if still:
            assert level < 2.0  # about the noise's mean absolute value (0.8 levels)


def test_the_masked_median_is_numpys_nanmedian_bit_for_bit():
    """masked_median against its reference, np.nanmedian with the others NaN, rounded as the plate rounds it: random
    values and keeps, odd and even counts, one kept value, none, every one, the ends of the range (0 and 255)."""
    rng = np.random.default_rng(3)
    values = rng.integers(0, 256, (37, 20, 24, 3)).astype(np.uint8)
    values[:, 0] = 255
    values[:, 1] = 0
    keep = rng.random((37, 20, 24)) < 0.4
    keep[:, 2, :] = False  # none
    keep[:, 3, :] = True  # every one
    keep[:, 4, :] = False
    keep[5, 4, :] = True  # one
    block = values.astype(np.float32)
    block[~keep] = np.nan
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        reference = np.nan_to_num(np.nanmedian(block, axis=0)).round().clip(0, 255).astype(np.uint8)
    counts = keep.sum(0)
    assert (counts % 2 == 0).any() and (counts % 2 == 1).any()  # both kinds of middle
    np.testing.assert_array_equal(masked_median(values, keep), reference)
