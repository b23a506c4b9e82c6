"""A capture's frames as the avatars see them: the camera of a frame, its pixels' ray directions, its image."""

from __future__ import annotations

import math

import numpy as np
from PIL import Image
from scipy.ndimage import distance_transform_edt

from models.capture.dataset import CaptureSplit, DatasetError
from render.camera import Camera


def camera_of(split: CaptureSplit, c2w: np.ndarray) -> Camera:
    _, fy, cx, cy = split.intrinsics
    if abs(cx - split.width / 2) > 0.5 or abs(cy - split.height / 2) > 0.5:
        raise DatasetError(f"{split.folder}: principal point ({cx}, {cy}) off the image centre is not supported yet")
    fov = math.degrees(2 * math.atan(0.5 * split.height / fy))
    return Camera(np.linalg.inv(c2w), fov, split.width, split.height, near_m=0.05, far_m=10.0)


def camera_directions(split: CaptureSplit) -> np.ndarray:
    """(H,W,3) camera-space ray directions (unit), OpenGL axes."""
    fx, fy, cx, cy = split.intrinsics
    j, i = np.meshgrid(np.arange(split.width) + 0.5, np.arange(split.height) + 0.5)
    d = np.stack([(j - cx) / fx, -(i - cy) / fy, -np.ones_like(j)], -1)
    return (d / np.linalg.norm(d, axis=-1, keepdims=True)).astype(np.float32)


def load_rgb(path, background: np.ndarray | None = None) -> np.ndarray:
    with Image.open(path) as im:
        a = np.asarray(im.convert("RGBA" if im.mode in ("RGBA", "LA") else "RGB"), np.float32) / 255.0
    if a.shape[-1] == 4:
        bg = np.ones(3, np.float32) if background is None else background
        a = a[..., :3] * a[..., 3:] + bg * (1 - a[..., 3:])
    return a


def load_mask(path) -> np.ndarray:
    """(H,W) coverage in [0,1]."""
    return np.asarray(Image.open(path).convert("L"), np.float32) / 255.0


def foreground_reach_m(hit: np.ndarray, depth: np.ndarray, mask: np.ndarray, focal_px: float) -> np.ndarray:
    """For each foreground pixel of a capture's mask (H,W) outside the mesh's silhouette (hit, (H,W)), how far
    (metres, at the nearest mesh pixel's depth) it lies from the silhouette: what an avatar must render beyond
    the mesh."""
    outside = (mask > 0.5) & ~hit
    if not outside.any() or not hit.any():
        return np.zeros(0, np.float32)
    dist_px, (ii, jj) = distance_transform_edt(~hit, return_indices=True)
    return (dist_px * depth[ii, jj] / focal_px)[outside].astype(np.float32)
