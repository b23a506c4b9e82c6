"""Image metrics checked against shifts made by hand."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter, shift

from models.training.metrics import image_offset_px


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
