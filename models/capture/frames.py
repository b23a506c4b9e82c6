"""A capture's frames as the avatars see them: the camera of a frame, its pixels' ray directions, its image."""

from __future__ import annotations

import math

import numpy as np
from PIL import Image
from scipy.ndimage import distance_transform_edt

from models.capture.dataset import CaptureSplit
from render.camera import Camera


def camera_of(split: CaptureSplit, c2w: np.ndarray) -> Camera:
    """A frame's camera: any pinhole (principal point anywhere, fx and fy apart); centred cameras with square
    pixels (within 1e-6 px) keep the centred form."""
    fx, fy, cx, cy = split.intrinsics
    view = np.linalg.inv(c2w)
    if max(abs(cx - split.width / 2), abs(cy - split.height / 2), abs(fx - fy)) < 1e-6:
        fov = math.degrees(2 * math.atan(0.5 * split.height / fy))
        return Camera(view, fov, split.width, split.height, near_m=0.05, far_m=10.0)
    return Camera.from_intrinsics(view, fx, fy, cx, cy, split.width, split.height, near_m=0.05, far_m=10.0)


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
