"""A foreground (head and shoulders) mask per frame, offline: OpenCV's GrabCut, seeded by the tracked face.

The face's landmark hull is certain foreground; a band around it and the region below the chin (neck,
shoulders) probable foreground; the crop's border rows and columns away from the neck probable background.
GrabCut's colour models then split the rest. (MediaPipe's selfie segmenter would do as well, but its model
is another download; this needs nothing but the landmarks.)
"""

from __future__ import annotations

import cv2
import numpy as np


def foreground_mask(rgb: np.ndarray, landmarks_px: np.ndarray, iterations: int = 3) -> np.ndarray:
    """(H,W) float32 mask in {0,1} for one (H,W,3) uint8 frame and its face landmarks (N,2) in its pixels."""
    h, w = rgb.shape[:2]
    mask = np.full((h, w), cv2.GC_PR_BGD, np.uint8)
    hull = cv2.convexHull(landmarks_px.astype(np.float32)).astype(np.int32)
    lo, hi = landmarks_px.min(0), landmarks_px.max(0)
    face_w, face_h = hi - lo
    # Probable foreground: the face hull grown (hair, ears), and a trapezoid below the chin (neck, shoulders).
    grown = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(grown, hull, 1)
    k = max(3, int(0.35 * face_w)) | 1
    grown = cv2.dilate(grown, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    cx = 0.5 * (lo[0] + hi[0])
    neck = np.array([[cx - 0.35 * face_w, hi[1] - 0.1 * face_h], [cx + 0.35 * face_w, hi[1] - 0.1 * face_h],
                     [cx + 0.9 * face_w, h], [cx - 0.9 * face_w, h]], np.int32)
    cv2.fillConvexPoly(grown, neck, 1)
    mask[grown > 0] = cv2.GC_PR_FGD
    # Certain foreground: the face hull shrunk a little.
    core = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(core, hull, 1)
    core = cv2.erode(core, np.ones((5, 5), np.uint8))
    mask[core > 0] = cv2.GC_FGD
    # Certain background: the top rows and the side columns' upper half.
    b = max(2, h // 40)
    mask[:b] = cv2.GC_BGD
    mask[: int(lo[1]), :b] = cv2.GC_BGD
    mask[: int(lo[1]), -b:] = cv2.GC_BGD
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.grabCut(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), mask, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    fg = ((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)).astype(np.uint8)
    # Keep the piece holding the face; fill its holes (eyes, mouth are foreground).
    n, labels = cv2.connectedComponents(fg)
    if n > 2:
        centre = np.clip(np.round(0.5 * (lo + hi)).astype(int), 0, [w - 1, h - 1])
        keep = labels[centre[1], centre[0]]
        fg = (labels == keep).astype(np.uint8) if keep else fg
    fg = cv2.morphologyEx(fg, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    return fg.astype(np.float32)
