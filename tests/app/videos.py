"""Reading back what the commands write: an mp4's frames and an 8-bit PSNR, shared by the command tests."""

from __future__ import annotations

import cv2
import numpy as np


def mp4_frames(path) -> list[np.ndarray]:
    """Every frame of a video file, RGB uint8."""
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            cap.release()
            return frames
        frames.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR of two uint8 images, dB."""
    return float(10 * np.log10(255.0**2 / np.mean((a.astype(float) - b.astype(float)) ** 2)))
