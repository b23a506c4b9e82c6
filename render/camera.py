"""Pinhole cameras in OpenGL axes (camera looks down -z, +y up): matrices and an orbit camera."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np


def look_at(eye: np.ndarray, target: np.ndarray, up: tuple[float, float, float] = (0.0, 1.0, 0.0)) -> np.ndarray:
    """World-to-camera 4x4 for a camera at `eye` looking at `target`, +y of the image towards `up`. An `up` along
    the view falls back to +z, or to +y where the view is along z too: a unit view cannot lie along both."""
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    f = target - eye
    distance = np.linalg.norm(f)
    if distance == 0:
        raise ValueError(f"look_at: eye and target coincide at {eye.tolist()}: no direction to look in")
    f /= distance
    for candidate in (up, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])):
        s = np.cross(f, candidate)
        if np.linalg.norm(s) >= 1e-9:
            break
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, near_m: float, far_m: float) -> np.ndarray:
    """OpenGL clip-from-camera projection, centred; depth maps [near, far] to NDC [-1, 1]."""
    t = 1.0 / math.tan(math.radians(fov_y_deg) / 2)
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1] = t / aspect, t
    p[2, 2] = (far_m + near_m) / (near_m - far_m)
    p[2, 3] = 2 * far_m * near_m / (near_m - far_m)
    p[3, 2] = -1.0
    return p


def pinhole_projection(fx_px: float, fy_px: float, cx_px: float, cy_px: float, width_px: int, height_px: int,
                       near_m: float, far_m: float) -> np.ndarray:
    """OpenGL clip-from-camera projection of a pinhole camera with pixel intrinsics (image x right, rows down,
    the principal point (cx, cy) measured from the top-left corner): a camera-space point (X, Y, Z), Z < 0,
    lands on pixel u = cx + fx X / -Z, v = cy - fy Y / -Z. Centred (cx = W/2, cy = H/2) it is `perspective`.

    >>> p = pinhole_projection(100.0, 100.0, 30.0, 20.0, 64, 48, 0.1, 10.0)
    >>> clip = p @ [0.1, 0.05, -1.0, 1.0]  # 10 cm right, 5 cm up, 1 m ahead
    >>> u, v = (clip[0] / clip[3] + 1) * 32, (1 - clip[1] / clip[3]) * 24
    >>> round(float(u), 6), round(float(v), 6)  # u = 30 + 100 * 0.1, v = 20 - 100 * 0.05
    (40.0, 15.0)
    """
    p = np.zeros((4, 4))
    p[0, 0], p[0, 2] = 2 * fx_px / width_px, 1 - 2 * cx_px / width_px
    p[1, 1], p[1, 2] = 2 * fy_px / height_px, 2 * cy_px / height_px - 1
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
    """A pinhole camera: world-to-camera view matrix, a vertical field of view, and where they differ from a
    centred camera with square pixels, the principal point and the horizontal focal length (a crop of a larger
    frame, a tracked video's camera)."""

    view: np.ndarray  # (4,4) world-to-camera
    fov_y_deg: float
    width_px: int
    height_px: int
    near_m: float = 0.05
    far_m: float = 5.0
    cx_px: float | None = None
    """Principal point from the left edge, pixels (None: the centre)."""
    cy_px: float | None = None
    """Principal point from the top edge, pixels (None: the centre)."""
    fx_px: float | None = None
    """Horizontal focal length, pixels (None: the vertical one, square pixels)."""

    @staticmethod
    def from_intrinsics(view: np.ndarray, fx_px: float, fy_px: float, cx_px: float, cy_px: float, width_px: int,
                        height_px: int, near_m: float = 0.05, far_m: float = 5.0) -> Camera:
        """A camera from pixel intrinsics (fx, fy, cx, cy)."""
        fov = math.degrees(2 * math.atan(0.5 * height_px / fy_px))
        return Camera(view, fov, width_px, height_px, near_m, far_m, float(cx_px), float(cy_px), float(fx_px))

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        """fx, fy, cx, cy in pixels."""
        fy = self.focal_px()
        return (fy if self.fx_px is None else self.fx_px, fy,
                0.5 * self.width_px if self.cx_px is None else self.cx_px,
                0.5 * self.height_px if self.cy_px is None else self.cy_px)

    @property
    def centred(self) -> bool:
        """Principal point at the centre and square pixels (every camera but a crop's or a tracked one's)."""
        return self.cx_px is None and self.cy_px is None and self.fx_px is None

    @property
    def projection(self) -> np.ndarray:
        if self.centred:
            return perspective(self.fov_y_deg, self.width_px / self.height_px, self.near_m, self.far_m)
        return pinhole_projection(*self.intrinsics, self.width_px, self.height_px, self.near_m, self.far_m)

    @property
    def position(self) -> np.ndarray:
        return np.linalg.inv(self.view)[:3, 3]

    def focal_px(self) -> float:
        """Focal length in pixels (vertical)."""
        return 0.5 * self.height_px / math.tan(math.radians(self.fov_y_deg) / 2)

    def resized(self, width_px: int, height_px: int) -> Camera:
        """The same view on an image of another size (the intrinsics scaled with it)."""
        if self.centred:
            return replace(self, width_px=width_px, height_px=height_px)
        fx, fy, cx, cy = self.intrinsics
        sx, sy = width_px / self.width_px, height_px / self.height_px
        return Camera.from_intrinsics(self.view, fx * sx, fy * sy, cx * sx, cy * sy, width_px, height_px,
                                      self.near_m, self.far_m)

    def cropped(self, left_px: int, top_px: int, width_px: int, height_px: int) -> Camera:
        """The camera of a crop of this camera's image: the same rays through the pixels they share."""
        fx, fy, cx, cy = self.intrinsics
        return Camera.from_intrinsics(self.view, fx, fy, cx - left_px, cy - top_px, width_px, height_px,
                                      self.near_m, self.far_m)


def clipping_around(camera: Camera, points: np.ndarray, margin_m: float = 0.15) -> Camera:
    """The camera with its near and far planes around `points` (N,3), world (the posed head: a translation control
    moves it anywhere), `margin_m` beyond them (hair and the field's shell reach past the mesh). Points behind the
    camera leave it as it is.

    >>> cam = Camera(np.eye(4), 30.0, 8, 8, near_m=0.5, far_m=0.6)
    >>> c = clipping_around(cam, np.array([[0.0, 0.0, -2.0], [0.0, 0.1, -3.0]]))
    >>> round(c.near_m, 3), round(c.far_m, 3)
    (1.85, 3.15)
    """
    p = np.asarray(points, np.float64)
    depth = -(p @ camera.view[:3, :3].T + camera.view[:3, 3])[:, 2]
    depth = depth[np.isfinite(depth)]
    if len(depth) == 0 or depth.max() <= 0:
        return camera
    near = max(1e-3, float(depth.min()) - margin_m, 1e-3 * float(depth.max()))
    return replace(camera, near_m=near, far_m=float(depth.max()) + margin_m)


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


TURNTABLE_ELEVATION_DEG = 5.0
"""A turntable's camera height above the head's centre, degrees: a little above the eyes, as a person looks."""
TURNTABLE_FOV_DEG = 18.0
"""A turntable's vertical field of view, degrees: a portrait lens's, the head filling the frame."""


def turntable_camera(vertices: np.ndarray, yaw_deg: float, pitch_deg: float = 0.0,
                     fov_y_deg: float = TURNTABLE_FOV_DEG,
                     width_px: int = 256, height_px: int = 256, margin: float = 1.06, zoom: float = 1.0) -> Camera:
    """An orbit camera for a turntable: it fits the vertices' cylinder about the vertical axis through their box's
    centre (its radius across, its height up), so the head fills the frame at every yaw, where framing_camera's
    bounding sphere (the neck's and the crown's corners counted in every direction) leaves it about half the
    frame's height."""
    v = np.asarray(vertices, np.float64)
    center = 0.5 * (v.min(0) + v.max(0))
    radius = float(np.linalg.norm((v - center)[:, [0, 2]], axis=1).max())
    half_h = 0.5 * float(v[:, 1].max() - v[:, 1].min())
    tan_y = math.tan(math.radians(fov_y_deg) / 2)
    tan_x = tan_y * width_px / height_px
    pitch = math.radians(abs(pitch_deg))
    # Seen from the front (or tilted), the cylinder's outline: its radius across, its height (and a tilted top)
    # up; the nearest point is `radius` in front of the axis.
    up = half_h * math.cos(pitch) + radius * math.sin(pitch)
    distance = radius + margin * max(up / tan_y, radius / tan_x) / max(zoom, 1e-3)
    cam = orbit_camera(yaw_deg, pitch_deg, distance, tuple(center), fov_y_deg, width_px, height_px)
    reach = float(np.linalg.norm(v - center, axis=1).max())
    return Camera(cam.view, fov_y_deg, width_px, height_px, near_m=max(0.01, distance - 2 * reach),
                  far_m=distance + 2 * reach)


def project(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points (M,3) on a camera's image: pixel x, y (continuous, pixel centres at k + 0.5) and depth along
    the view axis (metres; <= 0 behind the camera): x = cx + fx X / -Z, y = cy - fy Y / -Z."""
    cam = np.asarray(points, np.float64) @ camera.view[:3, :3].T + camera.view[:3, 3]
    depth = -cam[:, 2]
    fx, fy, cx, cy = camera.intrinsics
    safe = np.where(depth > 1e-9, depth, 1e-9)
    return cx + fx * cam[:, 0] / safe, cy - fy * cam[:, 1] / safe, depth
