"""Faces of any size in a video's frames. MediaPipe's landmarker is made for selfie distances: it sees the whole frame
shrunk to its detector's small input, so a face a tenth of a 1080p frame across (a man at a desk, someone across a
room) is a few pixels there and is not found. Where the whole frame shows no face, the finder looks in windows of
it (overlapping squares at a few scales, search_windows), and once a window has a face it follows it: each frame is
looked at through a window about the last face (follow_window), as a selfie camera would frame it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from models.tracking.landmarker import Face, Landmarker

FOLLOW_SIDE = 3.0
"""A window that follows the face is this many face widths across: the face fills a third of it, as in a selfie."""
MIN_WINDOW_PX = 64
"""The least side of a following window (a face of degenerate landmarks must not give an empty one)."""
SEARCH_SPLITS = (2, 3, 4)
"""The search looks at squares of the frame's shorter side over 2, 3 and 4, each overlapping its neighbours by half
(a face of 1/12 of a 1080p frame's height, 90 px, is then a third of a 270 px square)."""
SEARCH_EVERY = 10
"""With no face known, a frame in this many is searched window by window (the whole frame is looked at in every
one): a video without a face for a while does not cost the search on each frame."""


@dataclass(frozen=True)
class Window:
    """A square of a frame: its top-left corner and side, pixels."""

    x0: int
    y0: int
    side: int

    def cut(self, rgb: np.ndarray) -> np.ndarray:
        return rgb[self.y0:self.y0 + self.side, self.x0:self.x0 + self.side]


def search_windows(width: int, height: int, splits: tuple[int, ...] = SEARCH_SPLITS) -> list[Window]:
    """Squares of side min(W,H)/k for each k, stepped by half a side across the frame, the last flush with the edge.

    >>> [(w.x0, w.y0, w.side) for w in search_windows(400, 200, (2,))]
    [(0, 0, 100), (50, 0, 100), (100, 0, 100), (150, 0, 100), (200, 0, 100), (250, 0, 100), (300, 0, 100), \
(0, 50, 100), (50, 50, 100), (100, 50, 100), (150, 50, 100), (200, 50, 100), (250, 50, 100), (300, 50, 100), \
(0, 100, 100), (50, 100, 100), (100, 100, 100), (150, 100, 100), (200, 100, 100), (250, 100, 100), (300, 100, 100)]
    """
    out = []
    for k in splits:
        side = min(width, height) // k
        xs, ys = window_starts(width, side), window_starts(height, side)
        out += [Window(x, y, side) for y in ys for x in xs]
    return out


def window_starts(extent: int, side: int) -> list[int]:
    """Where windows of `side` start along an extent: every half side, the last flush with the end.

    >>> window_starts(250, 100)
    [0, 50, 100, 150]
    """
    starts = list(range(0, max(extent - side, 0) + 1, max(1, side // 2)))
    return starts if starts[-1] == max(extent - side, 0) else [*starts, extent - side]


def follow_window(face: Face, width: int, height: int, side_faces: float = FOLLOW_SIDE) -> Window:
    """A square about a face's landmarks, side_faces face widths across (at most the frame's shorter side), moved
    inside the frame.

    >>> lm = np.array([[100.0, 100.0], [140.0, 150.0]])
    >>> follow_window(Face(lm, np.zeros(2), {}, np.eye(4)), 640, 480)
    Window(x0=60, y0=65, side=120)
    """
    lo, hi = face.landmarks_px.min(0), face.landmarks_px.max(0)
    side = int(min(max(round(side_faces * float(hi[0] - lo[0])), MIN_WINDOW_PX), width, height))
    cx, cy = (lo + hi) / 2
    x0 = int(np.clip(round(cx - side / 2), 0, width - side))
    y0 = int(np.clip(round(cy - side / 2), 0, height - side))
    return Window(x0, y0, side)


def in_frame(face: Face, window: Window, frame_width: int) -> Face:
    """A face found in a window, in the frame's pixels (its depth in the frame's width units; its pose stays the
    window's: MediaPipe's pose assumes the camera saw the window)."""
    return replace(face, landmarks_px=face.landmarks_px + np.array([window.x0, window.y0], np.float32),
                   depth=face.depth * (window.side / frame_width))


class FaceFinder:
    """The faces in a video's frames (in time order), however small in the frame: the whole frame first (MediaPipe
    in video mode), then the window that follows the last face, then, with no face known, the search windows. Says
    how each frame's faces were found (`found_by`: "frame", "following" or "search"). A context manager."""

    def __init__(self, bundle: str | Path, max_faces: int = 2):
        self.whole = Landmarker(bundle, max_faces)
        self.windows = Landmarker(bundle, max_faces, video=False)
        self.last: Face | None = None
        self.since_search = SEARCH_EVERY
        self.found_by = ""

    def detect(self, rgb: np.ndarray, time_ms: int) -> list[Face]:
        h, w = rgb.shape[:2]
        faces = self.whole.detect(rgb, time_ms)
        self.found_by = "frame"
        if not faces and self.last is not None:
            window = follow_window(self.last, w, h)
            faces = [in_frame(f, window, w) for f in self.windows.detect(window.cut(rgb), time_ms)]
            self.found_by = "following"
        if not faces and self.last is None and self.since_search >= SEARCH_EVERY:
            faces, self.since_search = self.search(rgb), 0
            self.found_by = "search"
        self.since_search += 1
        self.last = max(faces, key=lambda f: float(np.ptp(f.landmarks_px[:, 0]))) if faces else None
        if not faces:
            self.found_by = ""
        return faces

    def search(self, rgb: np.ndarray) -> list[Face]:
        """The faces of the first window size that has any (the largest windows first), each found once (a face
        in two overlapping windows is kept from the one it sits in most squarely: the largest copy)."""
        h, w = rgb.shape[:2]
        for k in SEARCH_SPLITS:
            found = [in_frame(f, win, w) for win in search_windows(w, h, (k,))
                     for f in self.windows.detect(win.cut(rgb), 0)]
            if found:
                return distinct(found)
        return []

    def close(self) -> None:
        self.whole.close()
        self.windows.close()

    def __enter__(self) -> FaceFinder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def distinct(faces: list[Face]) -> list[Face]:
    """Faces found in overlapping windows, one per person: a face whose centre lies within half a face width of a
    wider one's is the same face.

    >>> a = Face(np.array([[0.0, 0.0], [10.0, 10.0]]), np.zeros(2), {}, np.eye(4))
    >>> b = Face(np.array([[1.0, 1.0], [10.0, 10.0]]), np.zeros(2), {}, np.eye(4))
    >>> c = Face(np.array([[50.0, 0.0], [60.0, 10.0]]), np.zeros(2), {}, np.eye(4))
    >>> [float(f.landmarks_px[0, 0]) for f in distinct([b, a, c])]
    [0.0, 50.0]
    """
    kept: list[Face] = []
    for f in sorted(faces, key=lambda f: -float(np.ptp(f.landmarks_px[:, 0]))):
        centre, width = f.landmarks_px.mean(0), float(np.ptp(f.landmarks_px[:, 0]))
        if all(np.linalg.norm(centre - k.landmarks_px.mean(0)) > 0.5 * max(width, float(np.ptp(k.landmarks_px[:, 0])))
               for k in kept):
            kept.append(f)
    return kept
