"""Which tracked frames train, which validate and which are held out: by time (the last part of the video, the
default) or by view (the frames where the head is turned furthest from its usual pose, to measure an avatar beyond
the views it was trained on). Pure functions of frame counts and head rotations."""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

SplitBy = Literal["time", "view"]
VAL_EVERY = 20
"""One frame in this many of those not held out validates (the tenth of each twenty)."""


def split_by_time(n: int, n_test: int) -> list[str]:
    """The last n_test frames are held out; of the rest, every VAL_EVERY-th (from the tenth) validates.

    >>> s = split_by_time(25, 3); s[-3:], s[10], s.count("train")
    (['test', 'test', 'test'], 'val', 21)
    """
    return ["test" if k >= n - n_test else "val" if k % VAL_EVERY == VAL_EVERY // 2 else "train" for k in range(n)]


def turn_from_usual_deg(rotations: np.ndarray) -> np.ndarray:
    """(N,) degrees between each frame's facing direction (its head rotation (N,3,3) applied to +z, out of the
    face) and the usual one (the normalised mean of them all): how far the head is turned, either way, up or down.

    >>> from scipy.spatial.transform import Rotation
    >>> r = Rotation.from_euler("y", [[0], [20], [40]], degrees=True).as_matrix()
    >>> turn_from_usual_deg(r).round(1).tolist()  # the usual facing is 20 degrees to the side
    [20.0, 0.0, 20.0]
    >>> turn_from_usual_deg(Rotation.from_euler("x", [[0], [30]], degrees=True).as_matrix()).round(1).tolist()
    [15.0, 15.0]
    """
    facing = np.asarray(rotations, np.float64)[:, :, 2]
    usual = facing.mean(0)
    usual /= max(np.linalg.norm(usual), 1e-12)
    return np.degrees(np.arccos(np.clip(facing @ usual, -1.0, 1.0)))


def split_by_view(rotations: np.ndarray, n_test: int) -> list[str]:
    """The n_test frames whose heads are turned furthest from the usual facing (turn_from_usual_deg) are held out;
    of the rest, in the video's order, every VAL_EVERY-th (from the tenth) validates. The avatar then trains on the
    smaller turns and is judged on views it never saw.

    >>> from scipy.spatial.transform import Rotation
    >>> r = Rotation.from_euler("y", np.array([0, 2, -3, 35, 1, -30, 0])[:, None], degrees=True).as_matrix()
    >>> split_by_view(r, 2)
    ['train', 'train', 'train', 'test', 'train', 'test', 'train']
    """
    n = len(rotations)
    turn = turn_from_usual_deg(rotations)
    held = set(np.argsort(-turn, kind="stable")[:n_test].tolist())
    out, rest = [], 0
    for k in range(n):
        if k in held:
            out.append("test")
        else:
            out.append("val" if rest % VAL_EVERY == VAL_EVERY // 2 else "train")
            rest += 1
    return out


def frame_splits(split_by: SplitBy, roots: np.ndarray, n_test: int) -> list[str]:
    """Every frame's split ("train", "val" or "test"), by time or by view; roots: (N,3) each frame's head rotation
    (the controls' root, axis-angle, radians)."""
    if split_by == "view":
        return split_by_view(Rotation.from_rotvec(np.asarray(roots, np.float64)).as_matrix(), n_test)
    return split_by_time(len(roots), n_test)
