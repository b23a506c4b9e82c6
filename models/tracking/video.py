"""Reading a video's frames at a chosen rate, and where each frame's image comes from: the face-centred square crop
every frame shares (one crop for the whole video keeps the camera's intrinsics fixed), or, where the head travels
so far that one crop would leave the face small, a crop that follows it (each frame its own window of one canvas,
so its own principal point)."""

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


def still_image(path: Path) -> bool:
    """Whether a file is a still picture (PNG, JPEG, a one-frame GIF...), told by its content: OpenCV reads one as
    a video of one frame."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            return not getattr(im, "is_animated", False)
    except (UnidentifiedImageError, OSError, ValueError):
        return False


def video_info(path: Path) -> VideoInfo:
    if not path.is_file():
        raise VideoError(f"{path}: no such video file")
    if still_image(path):
        raise VideoError(f"{path}: is an image, not a video (track needs a video of one face: mp4, mov, webm...)")
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
        """The crop of one frame at size x size, each output pixel the source's mean over its footprint.

        Coordinates are continuous, as the landmarks, the intrinsics and the rays have them (pixel k spans k to
        k + 1, its centre at k + 0.5): crop = (source - x0) scale. `warpAffine` has no area filter (INTER_AREA
        falls back to bilinear there), so a crop shrunk more than 2x would alias (2-pixel stripes shrunk 4x came
        out white, not grey): the frame is first reduced by the whole factor f = floor(1 / scale) with block means
        (reduced pixel i spans source f i to f i + f), then warped the rest of the way (at most 2x). warpAffine
        maps pixel indices, centre to centre: crop pixel d's centre d + 0.5 = (f (i + 0.5) - x0) scale, so
            d = f scale i + (f / 2 - x0) scale - 0.5."""
        f = int(1.0 / self.scale + 1e-6) if self.scale < 1 else 1
        if f >= 2:
            h, w = rgb.shape[0] // f * f, rgb.shape[1] // f * f
            rgb = cv2.resize(rgb[:h, :w], (w // f, h // f), interpolation=cv2.INTER_AREA)
        s = self.scale * f
        M = np.array([[s, 0, (f / 2 - self.x0) * self.scale - 0.5], [0, s, (f / 2 - self.y0) * self.scale - 0.5]])
        return cv2.warpAffine(rgb, M, (self.size, self.size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def cropped_frames(path: Path, fps: float | None, crop: Crop | list[Crop], wanted: list[int]) -> list[np.ndarray]:
    """The crops of the source frames numbered `wanted` (indices as `sampled_frames` gives them at `fps`; one crop
    for all, or each its own), read again from the file: a tracked video keeps only these small images, never its
    full frames (a minute of 4K video is 45 GB of RGB)."""
    crops = dict(zip(wanted, crop if isinstance(crop, list) else [crop] * len(wanted), strict=True))
    out: dict[int, np.ndarray] = {}
    for index, _, rgb in sampled_frames(path, fps):
        if index in crops:
            out[index] = crops[index].image(rgb)
            if len(out) == len(crops):
                break
    missing = crops.keys() - out.keys()
    if missing:
        raise VideoError(f"{path}: frame {min(missing)} could not be decoded a second time (the file changed?)")
    return [out[i] for i in wanted]


def face_boxes(landmarks_px: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, float]:
    """Each frame's face box, (N,2) least and most (source pixels), and how far below the box's middle a crop's
    centre goes (the neck rather than the air: 0.08 of the median face height)."""
    lo = np.stack([p.min(0) for p in landmarks_px])
    hi = np.stack([p.max(0) for p in landmarks_px])
    return lo, hi, 0.08 * float(np.median(hi[:, 1] - lo[:, 1]))


def one_crop(lo: np.ndarray, hi: np.ndarray, lower: float, margin: float, reach: float) -> tuple[np.ndarray, float]:
    """face_crop's centre (source pixels) and side before the frame bounds it, from face_boxes."""
    extent = float(np.max(hi - lo))
    centre = np.median(0.5 * (lo + hi), 0)
    centre[1] += lower
    travel = float(np.max(np.maximum(hi - centre, centre - lo)))  # farthest any face's edge gets from the centre
    return centre, max(margin * extent, 2 * (travel + reach * extent))


def face_crop(landmarks_px: list[np.ndarray], size: int, frame_wh: tuple[int, int], margin: float = 1.9,
              reach: float = 0.3) -> Crop:
    """One square crop about the face over all frames: centred on the median face centre (a little lower: the
    neck rather than the air), `margin` times the largest face extent seen (room for hair, ears and neck), and
    wider where the head travels: every frame's face box with `reach` times the face's extent beyond it (its
    hair and ears) stays inside. Kept inside the frame where the frame allows (no invented pixels).

    A face 100 px across that never moves: side 190 px; the same face 120 px right of its median place in one
    frame: that box's far edge is 50 + 120 = 170 px from the centre, so side = 2 (170 + 30) = 400 px."""
    centre, side = one_crop(*face_boxes(landmarks_px), margin, reach)
    side = min(side, float(min(frame_wh)))
    x0 = float(np.clip(centre[0] - side / 2, 0, frame_wh[0] - side))
    y0 = float(np.clip(centre[1] - side / 2, 0, frame_wh[1] - side))
    return Crop(x0, y0, side, size)


@dataclass(frozen=True)
class Framing:
    """Where each frame's image comes from: a canvas (the source frames at one scale, its pixel (0, 0) at source
    (x0, y0); width x height canvas pixels) and each frame's size x size window of it, its top-left at whole canvas
    pixels (offsets). A fixed crop is the canvas of one window that every frame shares (offsets all zero); a
    following crop's windows move with the head, and a frame's principal point is the canvas's less its offset."""

    x0: float
    y0: float
    side: float
    """A window's side in source pixels."""
    width: int
    height: int
    size: int
    offsets: np.ndarray  # (N,2) int, each frame's window's top-left (x, y) in canvas pixels

    @property
    def following(self) -> bool:
        return bool(np.any(self.offsets))

    @property
    def scale(self) -> float:
        return self.size / self.side

    def points(self, px: np.ndarray) -> np.ndarray:
        """Source-frame pixels (...,2) -> canvas pixels."""
        return (px - np.array([self.x0, self.y0], np.float32)) * self.scale

    def window(self, j: int) -> Crop:
        """Frame j's crop of the source (its window of the canvas)."""
        ox, oy = self.offsets[j]
        return Crop(self.x0 + ox / self.scale, self.y0 + oy / self.scale, self.side, self.size)

    @classmethod
    def fixed(cls, crop: Crop, frames: int) -> Framing:
        return cls(crop.x0, crop.y0, crop.side, crop.size, crop.size, crop.size, np.zeros((frames, 2), np.int64))


FOLLOW_WHEN = 1.25
"""A crop follows the head where one crop for the whole video would be this many times the side a still face
gets (the face at 80% of its size or less)."""

FOLLOW_SMOOTHING = 9
"""Frames the following window's centre is averaged over (the landmarks' jitter does not shake the frame)."""


def face_framing(landmarks_px: list[np.ndarray], size: int, frame_wh: tuple[int, int], follow: str = "auto",
                 margin: float = 1.9, reach: float = 0.3) -> Framing:
    """The framing of a video: face_crop's one crop ("fixed"), or ("follow") a window of a still face's side
    (`margin` times the largest face extent) about each frame's face, its centre smoothed over FOLLOW_SMOOTHING
    frames, kept inside the frame where the frame allows and placed at whole canvas pixels; "auto" follows where
    one crop would need FOLLOW_WHEN times that side or more (the frame may not even hold it: faces cut off).

    A 100 px face that pans 600 px right over 5 frames, 150 px a frame, in a 1920 x 1080 video, at size 190: one
    crop would be 2 (300 + 50 + 30) = 760 px (the face at a quarter of it), so the crop follows in 190 px windows
    (scale 1). Their centres, averaged over the 5 frames, lag the fast pan, so each window is held where the face
    and 30 px about it stay inside (its left edge within 440 to 470 px + 150 px a frame):

    >>> face = np.array([[500.0, 300.0], [600.0, 400.0]])
    >>> f = face_framing([face + [150.0 * k, 0.0] for k in range(5)], 190, (1920, 1080))
    >>> f.following, f.offsets[:, 0].tolist(), (f.width, f.height), f.x0
    (True, [0, 150, 285, 420, 570], (760, 190), 470.0)
    """
    n = len(landmarks_px)
    lo, hi, lower = face_boxes(landmarks_px)
    side = min(margin * float(np.max(hi - lo)), float(min(frame_wh)))
    # (one crop's side before the frame bounds it: a head that travels further than the frame is tall would leave
    # a crop the frame bounds)
    if follow == "fixed" or (follow == "auto" and one_crop(lo, hi, lower, margin, reach)[1] < FOLLOW_WHEN * side):
        return Framing.fixed(face_crop(landmarks_px, size, frame_wh, margin, reach), n)
    centre = 0.5 * (lo + hi)
    centre[:, 1] += lower
    k = min(FOLLOW_SMOOTHING, n)
    kernel = np.ones(k) / k
    padded = np.pad(centre, ((k // 2, k - 1 - k // 2), (0, 0)), mode="edge")
    centre = np.stack([np.convolve(padded[:, a], kernel, mode="valid") for a in range(2)], 1)
    # the smoothed window may lag a fast move: each frame's face and `reach` of it about it stay in its window
    pad = reach * (hi - lo).max(1, keepdims=True)
    corner = np.clip(centre - side / 2, np.minimum(hi + pad - side, lo - pad), lo - pad)
    corner = np.clip(corner, 0, np.array(frame_wh, np.float64) - side)
    scale = size / side
    origin = corner.min(0)
    offsets = np.round((corner - origin) * scale).astype(np.int64)
    return Framing(float(origin[0]), float(origin[1]), side, int(offsets[:, 0].max()) + size,
                   int(offsets[:, 1].max()) + size, size, offsets)
