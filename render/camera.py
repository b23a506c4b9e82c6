"""Pinhole cameras in OpenGL axes (camera looks down -z, +y up): matrices and an orbit camera."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def look_at(eye: np.ndarray, target: np.ndarray, up: tuple[float, float, float] = (0.0, 1.0, 0.0)) -> np.ndarray:
    """World-to-camera 4x4 for a camera at `eye` looking at `target`, +y of the image towards `up`."""
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:  # looking straight up or down: pick another up
        s = np.cross(f, np.array([0.0, 0.0, 1.0]))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, near_m: float, far_m: float) -> np.ndarray:
    """OpenGL clip-from-camera projection; depth maps [near, far] to NDC [-1, 1]."""
    t = 1.0 / math.tan(math.radians(fov_y_deg) / 2)
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1] = t / aspect, t
    p[2, 2] = (far_m + near_m) / (near_m - far_m)
    p[2, 3] = 2 * far_m * near_m / (near_m - far_m)
    p[3, 2] = -1.0
    return p


def orthographic(half_width_m: float, half_height_m: float, near_m: float, far_m: float) -> np.ndarray:
    p = np.eye(4)
    p[0, 0], p[1, 1] = 1 / half_width_m, 1 / half_height_m
    p[2, 2] = -2 / (far_m - near_m)
    p[2, 3] = -(far_m + near_m) / (far_m - near_m)
    return p


def linear_depth_from_ndc(depth01: np.ndarray, near_m: float, far_m: float) -> np.ndarray:
    """Metric distance along -z from a perspective depth-buffer value in [0, 1]."""
    ndc = 2.0 * depth01 - 1.0
    return 2.0 * near_m * far_m / (far_m + near_m - ndc * (far_m - near_m))


@dataclass(frozen=True)
class Camera:
    """A perspective camera: world-to-camera view matrix and a vertical field of view."""

    view: np.ndarray  # (4,4) world-to-camera
    fov_y_deg: float
    width_px: int
    height_px: int
    near_m: float = 0.05
    far_m: float = 5.0

    @property
    def projection(self) -> np.ndarray:
        return perspective(self.fov_y_deg, self.width_px / self.height_px, self.near_m, self.far_m)

    @property
    def position(self) -> np.ndarray:
        return np.linalg.inv(self.view)[:3, 3]

    def focal_px(self) -> float:
        """Focal length in pixels (vertical)."""
        return 0.5 * self.height_px / math.tan(math.radians(self.fov_y_deg) / 2)


def orbit_camera(yaw_deg: float = 0.0, pitch_deg: float = 0.0, distance_m: float = 0.6,
                 target: tuple[float, float, float] = (0.0, 0.0, 0.0), fov_y_deg: float = 30.0,
                 width_px: int = 512, height_px: int = 512) -> Camera:
    """A camera on a sphere around `target`: yaw turns about +y (positive moves it to the subject's
    left, +x), pitch raises it."""
    yaw, pitch = math.radians(yaw_deg), math.radians(pitch_deg)
    t = np.asarray(target, np.float64)
    eye = t + distance_m * np.array([math.sin(yaw) * math.cos(pitch), math.sin(pitch),
                                     math.cos(yaw) * math.cos(pitch)])
    return Camera(look_at(eye, t), fov_y_deg, width_px, height_px)


def framing_camera(vertices: np.ndarray, yaw_deg: float = 0.0, pitch_deg: float = 0.0, fov_y_deg: float = 30.0,
                   width_px: int = 512, height_px: int = 512, margin: float = 1.08, zoom: float = 1.0,
                   target_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Camera:
    """An orbit camera around the bounding box of `vertices` (V,3) that fits them in view; `zoom` divides
    that distance (2: twice as close), `target_offset` (metres, world) moves the point it looks at (pan)."""
    v = np.asarray(vertices, np.float64)
    center = 0.5 * (v.min(0) + v.max(0)) + np.asarray(target_offset, np.float64)
    radius = float(np.linalg.norm(v - center, axis=1).max())
    half_fov = math.radians(min(fov_y_deg, fov_y_deg * width_px / height_px)) / 2
    distance = margin * radius / math.sin(half_fov) / max(zoom, 1e-3)
    cam = orbit_camera(yaw_deg, pitch_deg, distance, tuple(center), fov_y_deg, width_px, height_px)
    return Camera(cam.view, fov_y_deg, width_px, height_px, near_m=max(0.01, distance - 2 * radius),
                  far_m=distance + 2 * radius)
