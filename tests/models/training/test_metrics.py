"""Image metrics checked against shifts made by hand."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter, shift

from models.training.metrics import edge_density, image_offset_px


@pytest.mark.parametrize(("dx", "dy"), [(3.0, -2.0), (-4.5, 1.25), (0.0, 0.0)])
def test_image_offset_finds_a_known_shift(dx, dy):
    """A smooth random image moved by (dx, dy) pixels (whole or sub-pixel, scipy's spline shift) is found that far
    from the original: whole pixels to a twentieth, half pixels to a third (phase correlation's peak is read to
sub-pixel by its neighbours, which pulls halves towards the nearer whole); a measure of renders pixels off."""
    rng = np.random.default_rng(3)
    truth = np.stack([gaussian_filter(rng.random((96, 96)), 1) for _ in range(3)], -1)
    truth = (truth - truth.min()) / np.ptp(truth)
    render = np.stack([shift(truth[..., c], (dy, dx), mode="wrap") for c in range(3)], -1)
    found = image_offset_px(render, truth)
    tolerance = [0.05 if float(v).is_integer() else 0.35 for v in (dx, dy)]
    assert abs(found[0] - dx) <= tolerance[0] and abs(found[1] - dy) <= tolerance[1], found


def _disc(size: int = 128, radius: float = 40.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A figure (a disc) on a room: its x, y pixel centres' offsets from the middle and its opacity."""
    y, x = np.mgrid[:size, :size] - (size - 1) / 2
    return x, y, (np.hypot(x, y) <= radius).astype(np.float32)


def test_edge_density_by_hand():
    """A disc of one colour has no edges within it (its outline against the room is eroded away); of a smooth
    gradient, none; split down the middle into two greys (a step of 0.3), one line of edge pixels the chord's length:
    about 76 of the 4 500 pixels inside (radius 38 after 2 px of erosion), 16.8 a thousand. A patchwork of 8 px
    squares in the same two greys: a line every 8 pixels each way, 76 / 8 lines each way of the disc's mean chord
    (4536 / 76 = 60 px), 250 a thousand by their length, fewer where Canny thins the lines' crossings (186 here):
    ten times the one step."""
    x, y, opacity = _disc()
    grey = np.full(opacity.shape + (3,), 0.4)
    assert edge_density(grey, opacity) == 0.0
    smooth = np.clip(0.3 + 0.4 * (x + 64) / 128, 0, 1)[..., None].repeat(3, -1)
    assert edge_density(smooth, opacity) == 0.0
    split = np.where(x[..., None] < 0, 0.3, 0.6).repeat(3, -1)
    assert 14.0 < edge_density(split, opacity) < 19.0
    squares = ((np.floor((x + 64) / 8) + np.floor((y + 64) / 8)) % 2)[..., None]
    patchwork = np.where(squares > 0, 0.3, 0.6).repeat(3, -1)
    assert 150.0 < edge_density(patchwork, opacity) < 260.0
    assert edge_density(split, np.zeros_like(opacity)) == 0.0  # no figure: nothing to count
