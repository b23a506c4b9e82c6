"""Reading a video's frames at a chosen rate, and the face-centred square crop every frame shares (one crop
for the whole video keeps the camera's intrinsics fixed)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np


class VideoError(ValueError):
    """A video that cannot be read; the message names the file and the problem."""


@dataclass(frozen=True)
class VideoInfo:
    width: int
    height: int
    fps: float
    frames: int


def video_info(path: Path) -> VideoInfo:
    if not path.is_file():
        raise VideoError(f"{path}: no such video file")
    cap = cv2.VideoCapture(str(path))
    try:
        ok, frame = cap.read() if cap.isOpened() else (False, None)
        if not ok or frame is None:
            raise VideoError(f"{path}: not a video this program can decode (no frame could be read)")
        fps = cap.get(cv2.CAP_PROP_FPS)
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        cap.release()
    return VideoInfo(frame.shape[1], frame.shape[0], fps if fps and fps > 0 else 30.0, count)


def sampled_frames(path: Path, fps: float | None) -> Iterator[tuple[int, float, np.ndarray]]:
    """(source frame index, time in seconds, RGB uint8 frame) at about `fps` frames a second (every frame
    when None or when the video is slower)."""
    info = video_info(path)
    step = 1.0 if not fps or fps >= info.fps else info.fps / fps
    cap = cv2.VideoCapture(str(path))
    index, next_take = 0, 0.0
    try:
        while True:
            ok, bgr = cap.read()
            if not ok:
                break
            if index >= next_take - 1e-6:
                yield index, index / info.fps, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                next_take += step
            index += 1
    finally:
        cap.release()


@dataclass(frozen=True)
class Crop:
    """A square window of the source frames (may reach past their edges: padded by replication), shown at
    `size` pixels."""

    x0: float
    y0: float
    side: float
    size: int

    @property
    def scale(self) -> float:
        return self.size / self.side

    def points(self, px: np.ndarray) -> np.ndarray:
        """Source-frame pixels (...,2) -> crop pixels."""
        return (px - np.array([self.x0, self.y0], np.float32)) * self.scale

    def image(self, rgb: np.ndarray) -> np.ndarray:
        """The crop of one frame at size x size."""
        M = np.array([[self.scale, 0, -self.x0 * self.scale], [0, self.scale, -self.y0 * self.scale]], np.float64)
        return cv2.warpAffine(rgb, M, (self.size, self.size), flags=cv2.INTER_AREA if self.scale < 1
                              else cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def face_crop(landmarks_px: list[np.ndarray], size: int, frame_wh: tuple[int, int], margin: float = 1.9) -> Crop:
    """One square crop about the face over all frames: centred on the median face centre, `margin` times the
    largest face extent seen (room for hair, ears, neck and head motion), kept inside the frame where the frame
    allows (no invented pixels)."""
    lo = np.stack([p.min(0) for p in landmarks_px])
    hi = np.stack([p.max(0) for p in landmarks_px])
    centre = np.median(0.5 * (lo + hi), 0)
    centre[1] += 0.08 * float(np.median(hi[:, 1] - lo[:, 1]))  # a little lower: the neck rather than the air
    side = min(margin * float(np.max(hi - lo)), float(min(frame_wh)))
    x0 = float(np.clip(centre[0] - side / 2, 0, frame_wh[0] - side))
    y0 = float(np.clip(centre[1] - side / 2, 0, frame_wh[1] - side))
    return Crop(x0, y0, side, size)
