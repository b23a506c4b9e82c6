"""A foreground (head and shoulders) mask per frame, offline: MediaPipe's selfie segmenter where the set-up
installed its model (segmenter.py), else OpenCV's GrabCut, seeded by the tracked face.

GrabCut: the face's landmark hull is certain foreground; a wide band around it and the region below the chin
(neck, shoulders) probable foreground; the upper corners beside the head certain background. GrabCut's colour
models then split the rest. Against true masks it does as well as the segmenter before a plain wall, and misses
hair, or takes in the room, where the room has the hair's colours (benchmarks/bench_masks.py, docs/tracking.md).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable

import cv2
import numpy as np

from models.tracking.segmenter import PersonSegmenter, face_piece, installed_model

MASK_WAYS = ("auto", "selfie", "grabcut")
"""How `track` cuts its masks: auto is the selfie segmenter where its model is installed, else GrabCut."""


class MaskWayError(ValueError):
    """A way of cutting masks that cannot run here (the segmenter asked for, its model not installed)."""


def mask_way(asked: str = "auto") -> str:
    """The way masks are cut for `asked` (MASK_WAYS): selfie or grabcut."""
    if asked not in MASK_WAYS:
        raise MaskWayError(f"masks: {asked!r} is not one of {', '.join(MASK_WAYS)}")
    if asked == "grabcut":
        return "grabcut"
    if installed_model() is None:
        if asked == "selfie":
            raise MaskWayError("masks: the selfie segmenter's model is not installed (make setup installs it, "
                               "or use --masks grabcut)")
        return "grabcut"
    return "selfie"


GRABCUT_SAMPLES = 10
"""Background and foreground pixels GrabCut needs at least (each colour model has five components); a frame that
the person fills (a crop close about a large head), or one the face has left (a fixed crop the frame bounds), keeps
the seeds as they are."""


def foreground_masks(frames: list[np.ndarray], landmarks_px: list[np.ndarray], workers: int | None = None,
                     progress: Callable[[int, int], None] | None = None, way: str = "grabcut") -> list[np.ndarray]:
    """The mask of every frame (with its landmarks), in the frames' order, cut the way given (mask_way's): selfie,
    the segmenter's person (PersonSegmenter.mask, in this process: 4 ms a frame); grabcut, foreground_mask's, in as
    many processes as the machine has cores (GrabCut runs on one): the same masks as one by one. progress(done,
    total) as they come."""
    if way == "selfie":
        segmenter = PersonSegmenter(installed_model())
        try:
            masks = []
            for k, (rgb, points) in enumerate(zip(frames, landmarks_px, strict=True)):
                masks.append(segmenter.mask(rgb, points))
                if progress:
                    progress(k + 1, len(frames))
            return masks
        finally:
            segmenter.close()
    workers = min(workers or len(os.sched_getaffinity(0)), len(frames))  # the cores this process may use
    jobs = list(zip(frames, landmarks_px, strict=True))
    if workers <= 1 or len(jobs) < 2 * workers:
        masks = []
        for k, job in enumerate(jobs):
            masks.append(_mask_of(job))
            if progress:
                progress(k + 1, len(jobs))
        return masks
    # spawn, not fork: the caller's threads (torch, MediaPipe) must not be copied mid-flight into the workers
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        masks = []
        for mask in pool.imap(_mask_of, jobs, chunksize=4):
            masks.append(mask)
            if progress:
                progress(len(masks), len(jobs))
    return masks


def _mask_of(job: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    return foreground_mask(*job)


def grabcut(rgb: np.ndarray, mask: np.ndarray, landmarks_px: np.ndarray, iterations: int = 3) -> np.ndarray:
    """GrabCut from seeds (mask (H,W) of cv2.GC_* labels): the foreground's piece holding the face (its landmarks
    (N,2)), closed over 5 px, as a float32 {0,1} mask. A frame with too few pixels of either kind to model keeps the
    seeds as they are."""
    room = np.count_nonzero((mask == cv2.GC_BGD) | (mask == cv2.GC_PR_BGD))
    if room < GRABCUT_SAMPLES or mask.size - room < GRABCUT_SAMPLES:  # the person fills the frame, or left it
        return ((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)).astype(np.float32)  # the seeds, as they are
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)  # GrabCut's k-means draws from OpenCV's global generator: each frame's mask its own, in any order
    cv2.grabCut(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), mask, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    fg = ((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)).astype(np.uint8)
    # Keep the piece holding the face; close its gaps (eyes, mouth are foreground).
    fg = cv2.morphologyEx(face_piece(fg, landmarks_px), cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    return fg.astype(np.float32)


def foreground_mask(rgb: np.ndarray, landmarks_px: np.ndarray, iterations: int = 3) -> np.ndarray:
    """(H,W) float32 mask in {0,1} for one (H,W,3) uint8 frame and its face landmarks (N,2) in its pixels, by GrabCut
    seeded from the face alone."""
    h, w = rgb.shape[:2]
    mask = np.full((h, w), cv2.GC_PR_BGD, np.uint8)
    hull = cv2.convexHull(landmarks_px.astype(np.float32)).astype(np.int32)
    lo, hi = landmarks_px.min(0), landmarks_px.max(0)
    face_w, face_h = hi - lo
    # Probable foreground: the face hull grown by half the face's width (hair, ears), and below the chin a
    # trapezoid widening to the shoulders (neck, collar). Wide on purpose: what lies outside it teaches GrabCut
    # the background's colours, and hair left there would teach it that hair is background.
    grown = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(grown, hull, 1)
    k = max(3, int(0.6 * face_w)) | 1
    grown = cv2.dilate(grown, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    cx = 0.5 * (lo[0] + hi[0])
    neck = np.array([[cx - 0.45 * face_w, hi[1] - 0.1 * face_h], [cx + 0.45 * face_w, hi[1] - 0.1 * face_h],
                     [cx + 1.2 * face_w, h], [cx - 1.2 * face_w, h]], np.int32)
    cv2.fillConvexPoly(grown, neck, 1)
    mask[grown > 0] = cv2.GC_PR_FGD
    # Certain foreground: the face hull shrunk a little.
    core = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(core, hull, 1)
    core = cv2.erode(core, np.ones((5, 5), np.uint8))
    mask[core > 0] = cv2.GC_FGD
    # Certain background: the upper corners, beside the head and above the shoulders (hair may reach the top row
    # above the head itself).
    side = int(0.9 * face_w)
    top = int(hi[1])
    mask[:top, : max(0, int(lo[0]) - side)] = cv2.GC_BGD
    mask[:top, min(w, int(hi[0]) + side):] = cv2.GC_BGD
    return grabcut(rgb, mask, landmarks_px, iterations)


def background_plate(frames: list[np.ndarray], masks: list[np.ndarray], grow_px: int, min_share: float = 0.2,
                     offsets: np.ndarray | None = None, canvas_wh: tuple[int, int] | None = None
                     ) -> tuple[np.ndarray, float]:
    """The room behind the person as a fixed camera saw it (the background NerFACE composites over): per pixel
    the median of the frames (H,W,3 uint8) in which the person's mask (H,W), grown by grow_px, leaves it free;
    pixels free in fewer than min_share of the frames that see them, or fewer than 3 (behind the person, or a
    mask that missed hair, most of the time), are inpainted from their surroundings. Frames of a following crop
    each cover their window of a larger canvas (offsets (N,2): each window's top-left in it; canvas_wh its size).
    Returns the plate (H,W,3) uint8 (the canvas's size) and the share of its pixels inpainted.

    A pixel the room shows in a fifth of the frames is better as the median of those than inpainted: the plate
    against the held-out frames of the three shared clips, on their masks' background, at 256 px: 31.8 / 24.9 /
    34.6 dB (talking_hdtf, expressions_d3, expressions_d19) with a grow of 1% of the image and min_share 0.2,
    26.6 / 23.6 / 33.5 with 3% and 0.5; 0.05 was better on two clips and 1.1 dB worse on d3, whose masks miss
    hair."""
    fh, fw = frames[0].shape[:2]
    offsets = np.zeros((len(frames), 2), np.int64) if offsets is None else np.asarray(offsets)
    w, h = canvas_wh or (fw, fh)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1, 2 * grow_px + 1))
    free = np.zeros((len(frames), h, w), bool)  # (N,H,W) the room seen, on the canvas
    seen = np.zeros((h, w), np.int64)  # how many frames' windows hold each canvas pixel
    for k, ((ox, oy), m) in enumerate(zip(offsets, masks, strict=True)):
        free[k, oy:oy + fh, ox:ox + fw] = cv2.dilate((m > 0.5).astype(np.uint8), kernel) == 0
        seen[oy:oy + fh, ox:ox + fw] += 1
    plate = np.zeros((h, w, 3), np.uint8)
    # at least 3 frames' word for a pixel (one frame's mask may miss hair), or every one where fewer hold it (the
    # edges of a following crop's canvas); none hold a corner no window reached: inpainted
    need = np.maximum(np.maximum(np.minimum(3, seen), np.ceil(min_share * seen)), 1)
    rows = max(1, (1 << 22) // (len(frames) * w * 3))  # a few million values at a time
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        block = np.zeros((len(frames), r1 - r0, w, 3), np.uint8)  # (N,h',W,3)
        for k, ((ox, oy), f) in enumerate(zip(offsets, frames, strict=True)):
            a, b = max(r0, oy), min(r1, oy + fh)
            if a < b:
                block[k, a - r0:b - r0, ox:ox + fw] = f[a - oy:b - oy]
        plate[r0:r1] = masked_median(block, free[:, r0:r1])  # pixels no frame frees: 0, inpainted below
    hole = (free.sum(0) < need).astype(np.uint8)
    if hole.all():
        return np.zeros_like(plate) + np.median(np.stack(frames).reshape(-1, 3), 0).astype(np.uint8), 1.0
    if hole.any():
        plate = cv2.inpaint(plate, hole, 5, cv2.INPAINT_TELEA)
    return plate, float(hole.mean())


def masked_median(values: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """(H,W,C) uint8: per pixel and channel the median of values (N,H,W,C) uint8 over the N where keep (N,H,W) is
    true (of two middle values their mean, rounded half to even), 0 where none is: what np.nanmedian gives with the
    others NaN, rounded, bit for bit (tests/models/tracking/test_masks.py), 7-8 times faster (192 frames of 256 px:
    1.1 s against 8.5). The kept values sort first in a radix sort of 16-bit numbers whose others are 256.

    >>> v = np.array([[[[10]]], [[[200]]], [[[30]]], [[[7]]]], np.uint8)  # (4,1,1,1)
    >>> int(masked_median(v, np.array([1, 1, 1, 0], bool)[:, None, None])[0, 0, 0])  # 10, 30, 200
    30
    >>> int(masked_median(v, np.array([1, 0, 1, 0], bool)[:, None, None])[0, 0, 0])  # (10 + 30) / 2
    20
    >>> int(masked_median(v, np.zeros(4, bool)[:, None, None])[0, 0, 0])
    0
    """
    n_frames = values.shape[0]
    v = np.where(keep[..., None], values.astype(np.uint16), np.uint16(256)).transpose(1, 2, 3, 0)  # (H,W,C,N)
    v = np.sort(v, axis=-1, kind="stable")  # numpy sorts 16-bit numbers by radix: linear in N
    n = keep.sum(0)[..., None, None]  # (H,W,1,1)
    lo = np.take_along_axis(v, np.maximum((n - 1) // 2, 0), -1)[..., 0].astype(np.float32)
    hi = np.take_along_axis(v, np.minimum(n // 2, n_frames - 1), -1)[..., 0].astype(np.float32)
    return np.where(n[..., 0] > 0, (lo + hi) / 2, 0).round().clip(0, 255).astype(np.uint8)


def own_room(frame: np.ndarray, mask: np.ndarray, grow_px: int, work_px: int = 64) -> np.ndarray:
    """(H,W,3) uint8 the room behind the person as this frame saw it: the frame where the person's mask (H,W), grown
    by grow_px, leaves it free; under the person, the room filled from around it (OpenCV's Telea inpainting at
    work_px, scaled up: the avatar covers most of it, and only its soft edges and hair show the fill).

    >>> f = np.zeros((32, 32, 3), np.uint8); f[:, :16] = (200, 0, 0); f[:, 16:] = (0, 0, 200)
    >>> m = np.zeros((32, 32), np.float32); m[8:24, 12:20] = 1; f[m > 0] = (0, 255, 0)
    >>> room = own_room(f, m, 1, work_px=16)
    >>> room[16, 4].tolist(), room[16, 28].tolist(), int(room[16, 13, 1]) < 60  # the room kept; no green left
    ([200, 0, 0], [0, 0, 200], True)
    """
    h, w = mask.shape
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1, 2 * grow_px + 1))
    person = cv2.dilate((mask > 0.5).astype(np.uint8), kernel)
    if not person.any():
        return frame.copy()
    if person.all():
        return np.zeros_like(frame) + np.median(frame.reshape(-1, 3), 0).astype(np.uint8)
    scale = work_px / max(h, w)
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    small = cv2.resize(frame, size, interpolation=cv2.INTER_AREA)
    hole = cv2.dilate(cv2.resize(person, size, interpolation=cv2.INTER_NEAREST), np.ones((3, 3), np.uint8))
    filled = cv2.resize(cv2.inpaint(small, hole, 3, cv2.INPAINT_TELEA), (w, h), interpolation=cv2.INTER_LINEAR)
    return np.where(person[..., None] > 0, filled, frame)


STILL_ROOM_LEVELS = 5.0
"""A room that differs from its plate by more than this (8-bit levels, the frames' median of their mean) is not
still: measured on the tracked clips of ../shared/data/video at 256 px, cameras on a tripod 0.3-2.3 (d3, d19,
talking_hdtf, five of more/), a camera moving through a room 18.6 (wide_room_plants), sea and a moving street
behind 8.5 and 10.0 (portrait_seaside, singing_boy)."""


def room_residual(frames: list[np.ndarray], masks: list[np.ndarray], plate: np.ndarray, grow_px: int,
                  offsets: np.ndarray | None = None) -> float:
    """How far the room in the frames is from the plate: per frame the mean absolute difference (8-bit levels,
    over the channels) of the pixels the person's mask grown by grow_px leaves free, its window of the plate
    where the crop follows; the median over the frames. A still camera's room differs by its noise; one that
    moves (or water, traffic) by much more (STILL_ROOM_LEVELS)."""
    fh, fw = frames[0].shape[:2]
    offsets = np.zeros((len(frames), 2), np.int64) if offsets is None else np.asarray(offsets)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1, 2 * grow_px + 1))
    levels = []
    for (ox, oy), f, m in zip(offsets, frames, masks, strict=True):
        room = cv2.dilate((m > 0.5).astype(np.uint8), kernel) == 0
        if room.any():
            window = plate[oy:oy + fh, ox:ox + fw].astype(np.float64)
            levels.append(float(np.abs(f.astype(np.float64) - window)[room].mean()))
    return float(np.median(levels)) if levels else 0.0
