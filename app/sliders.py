"""The sliders and the orbit camera as values: what the studio's Controls panel and viewport hold (app/studio/
session.py), what an animation keys and plays (app/animation.py), and what `animate` starts from. Plain values and
conversions: no GL, no widgets."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from models.head.controls import Controls
from render.camera import Camera, framing_camera


def euler_to_rotvec(yaw_deg: float, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """Axis-angle (3,) of a head turned by yaw (about +y), then pitch (about +x), then roll (about +z)."""
    return Rotation.from_euler("YXZ", [yaw_deg, pitch_deg, roll_deg], degrees=True).as_rotvec().astype(np.float32)


def rotvec_to_euler(rotvec: np.ndarray) -> np.ndarray:
    """The inverse of euler_to_rotvec, degrees (yaw, pitch, roll)."""
    return Rotation.from_rotvec(np.asarray(rotvec, np.float64)).as_euler("YXZ", degrees=True).astype(np.float32)


@dataclass
class Sliders:
    """The controls as the Controls panel holds them (degrees where a person thinks in degrees)."""

    expression: np.ndarray
    head: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))  # yaw, pitch, roll
    neck: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    jaw_open_deg: float = 0.0
    gaze_linked: bool = True
    gaze_left: np.ndarray = field(default_factory=lambda: np.zeros(2, np.float32))  # yaw, pitch
    gaze_right: np.ndarray = field(default_factory=lambda: np.zeros(2, np.float32))
    shape: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))  # the capture's identity

    def controls(self) -> Controls:
        right = self.gaze_left if self.gaze_linked else self.gaze_right
        return Controls(shape=self.shape, expression=self.expression.copy(),
                        root=euler_to_rotvec(*self.head), neck=euler_to_rotvec(*self.neck),
                        jaw=np.array([math.radians(self.jaw_open_deg), 0, 0], np.float32),
                        gaze_left=euler_to_rotvec(self.gaze_left[0], self.gaze_left[1], 0),
                        gaze_right=euler_to_rotvec(right[0], right[1], 0))

    @staticmethod
    def of(controls: Controls, n_expression: int) -> Sliders:
        """Sliders showing given controls (a capture frame's)."""
        expr = np.zeros(n_expression, np.float32)
        expr[: min(n_expression, len(controls.expression))] = controls.expression[:n_expression]
        gl, gr = rotvec_to_euler(controls.gaze_left), rotvec_to_euler(controls.gaze_right)
        return Sliders(expr, rotvec_to_euler(controls.root), rotvec_to_euler(controls.neck),
                       math.degrees(float(controls.jaw[0])), bool(np.allclose(gl, gr, atol=1e-3)),
                       gl[:2].copy(), gr[:2].copy(), np.asarray(controls.shape, np.float32))


def sliders_json(s: Sliders) -> dict:
    """The sliders as plain numbers (scripted runs' reports)."""
    r = lambda v: [round(float(x), 5) for x in v]
    return {"expression": r(s.expression), "head": r(s.head), "neck": r(s.neck),
            "jaw_open_deg": round(float(s.jaw_open_deg), 5), "gaze_left": r(s.gaze_left), "gaze_right": r(s.gaze_right)}


@dataclass
class View:
    """The orbit camera."""

    yaw_deg: float = 20.0
    pitch_deg: float = 5.0
    zoom: float = 1.0
    fov_deg: float = 18.0
    pan: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))

    def camera(self, vertices: np.ndarray, width: int, height: int) -> Camera:
        return framing_camera(vertices, self.yaw_deg, self.pitch_deg, self.fov_deg, width, height, zoom=self.zoom,
                              target_offset=tuple(self.pan))

    def orbit(self, dx_px: float, dy_px: float) -> None:
        self.yaw_deg = (self.yaw_deg - 0.4 * dx_px + 180) % 360 - 180
        self.pitch_deg = float(np.clip(self.pitch_deg + 0.4 * dy_px, -85, 85))

    def pan_by(self, dx_px: float, dy_px: float, camera: Camera) -> None:
        """Move the target with the mouse, in the camera's plane (about a pixel per pixel at the head)."""
        c2w = np.linalg.inv(camera.view)
        scale = 2 * math.tan(math.radians(camera.fov_y_deg) / 2) * np.linalg.norm(camera.position) / camera.height_px
        self.pan = (self.pan - c2w[:3, 0] * dx_px * scale + c2w[:3, 1] * dy_px * scale).astype(np.float32)

    def zoom_by(self, wheel: float) -> None:
        self.zoom = float(np.clip(self.zoom * 1.1**wheel, 0.25, 8.0))
