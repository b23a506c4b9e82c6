"""Image metrics: PSNR, SSIM, FaceMSE (over the face mask), normal angular error, correlation."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter


def psnr(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None) -> float:
    """10 log10(1 / MSE) for images in [0, 1]."""
    err = (np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2
    mse = err[mask].mean() if mask is not None else err.mean()
    return float(10 * np.log10(1.0 / max(mse, 1e-12)))


def ssim(a: np.ndarray, b: np.ndarray, sigma: float = 1.5) -> float:
    """Structural similarity (Wang et al. 2004) with a Gaussian window, mean over pixels and channels."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    c1, c2 = 0.01**2, 0.03**2
    blur = lambda x: gaussian_filter(x, sigma=(sigma, sigma, 0) if x.ndim == 3 else sigma, truncate=3.5)
    mu_a, mu_b = blur(a), blur(b)
    va, vb, cov = blur(a * a) - mu_a**2, blur(b * b) - mu_b**2, blur(a * b) - mu_a * mu_b
    s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a**2 + mu_b**2 + c1) * (va + vb + c2))
    return float(s.mean())


def face_mse(a: np.ndarray, b: np.ndarray, face_mask: np.ndarray) -> float:
    """Mean squared error over the face mask's pixels (all channels)."""
    return float(((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)[face_mask].mean())


def normal_angles_deg(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(N,) angles in degrees between two normal maps (...,3) at the mask's N pixels.

    >>> normal_angles_deg(np.array([[0.0, 0, 1], [0, 1, 1]]), np.array([[0.0, 0, 2], [0, 0, 1]]),
    ...                   np.array([True, True])).round(3).tolist()
    [0.0, 45.0]
    """
    p = pred[mask] / np.maximum(np.linalg.norm(pred[mask], axis=-1, keepdims=True), 1e-12)
    t = truth[mask] / np.maximum(np.linalg.norm(truth[mask], axis=-1, keepdims=True), 1e-12)
    return np.degrees(np.arccos(np.clip((p * t).sum(-1), -1, 1)))


def normal_angle_deg(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    """Mean angle in degrees between unit normal maps over the mask."""
    return float(normal_angles_deg(pred, truth, mask).mean())


def pearson(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """Correlation of two (H,W) maps over the mask's pixels; 0 where either is constant there."""
    x, y = np.asarray(a, np.float64)[mask], np.asarray(b, np.float64)[mask]
    x, y = x - x.mean(), y - y.mean()
    denom = np.sqrt((x * x).sum() * (y * y).sum())
    return float((x * y).sum() / denom) if denom > 1e-12 else 0.0


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of linear RGB (...,3)."""
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def image_offset_px(render: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(dx, dy) pixels that `render` (H,W,3) sits from `truth`: the shift that moves the truth onto the render, by
    phase correlation of their luminance (OpenCV's, Hann-windowed; sub-pixel). How far a held-out frame renders from
    where the video has the person."""
    import cv2

    a, b = (np.ascontiguousarray(luminance(np.asarray(x, np.float64))) for x in (truth, render))
    window = cv2.createHanningWindow(a.shape[::-1], cv2.CV_64F)
    (dx, dy), _ = cv2.phaseCorrelate(a, b, window)
    return float(dx), float(dy)


EDGE_THRESHOLDS = (20, 50)
"""Canny's hysteresis thresholds on 8-bit luminance (edge_density)."""


def edge_density(rgb: np.ndarray, opacity: np.ndarray, erode_px: int = 2) -> float:
    """Edge pixels per 1000 pixels of the figure: Canny's edges (EDGE_THRESHOLDS) of the render's 8-bit luminance,
    after a 3x3 Gaussian of sigma 0.7, within the figure (opacity (H,W) above 0.5, eroded by erode_px so that its
    outline against the room does not count). Where an avatar is seen beyond its capture's views, smooth hair has few
    and a patchwork of boxes in two colours many (their edges); 0 for a figure of one colour. rgb (H,W,3) in 0..1."""
    import cv2

    lum = np.round(np.clip(luminance(np.asarray(rgb, np.float64)), 0.0, 1.0) * 255).astype(np.uint8)
    figure = (np.asarray(opacity) > 0.5).astype(np.uint8)
    if erode_px > 0:
        figure = cv2.erode(figure, np.ones((2 * erode_px + 1,) * 2, np.uint8))
    area = int(figure.sum())
    if area == 0:
        return 0.0
    edges = cv2.Canny(cv2.GaussianBlur(lum, (3, 3), 0.7), *EDGE_THRESHOLDS) > 0
    return 1000.0 * float((edges & (figure > 0)).sum()) / area
