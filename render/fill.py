"""Filling an image's unknown pixels from the known ones around them (a baked texture's texels no view saw, a
person's chart texels no frame saw)."""

from __future__ import annotations

import cv2
import numpy as np


def push_pull(image: np.ndarray, known: np.ndarray) -> np.ndarray:
    """(H,W,C) the image with its unknown pixels filled from around: pull (halve the size, each pixel the mean of
    the known pixels under it, down to one pixel), then push (from the coarsest, each unknown pixel takes the
    coarser level's colour there, bilinearly upsampled). Known pixels keep their values exactly.

    >>> img = np.array([[[1.0], [0.0]], [[0.0], [3.0]]])
    >>> push_pull(img, np.eye(2, dtype=bool))[..., 0].tolist()  # one level up: the mean of 1 and 3 fills both
    [[1.0, 2.0], [2.0, 3.0]]
    """
    levels = []
    c = np.where(known[..., None], image, 0.0).astype(np.float64)
    w = known.astype(np.float64)
    while max(w.shape) > 1:
        levels.append((c, w))
        h, wd = w.shape
        c = np.pad(c, ((0, h % 2), (0, wd % 2), (0, 0)))
        w = np.pad(w, ((0, h % 2), (0, wd % 2)))
        c = c[0::2, 0::2] + c[1::2, 0::2] + c[0::2, 1::2] + c[1::2, 1::2]
        w = w[0::2, 0::2] + w[1::2, 0::2] + w[0::2, 1::2] + w[1::2, 1::2]
    fill = np.where(w[..., None] > 0, c / np.maximum(w, 1e-12)[..., None], 0.0)
    for c, w in reversed(levels):
        up = cv2.resize(fill, (2 * fill.shape[1], 2 * fill.shape[0]), interpolation=cv2.INTER_LINEAR)
        up = up.reshape(*up.shape[:2], -1)[: w.shape[0], : w.shape[1]]
        fill = np.where(w[..., None] > 0, c / np.maximum(w, 1e-12)[..., None], up)
    return fill.astype(image.dtype)
