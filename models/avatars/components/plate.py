"""A tracked video's background plate: what its fixed camera saw behind the person (the room), kept with the
avatar's weights. Rays of that camera (or of a frame's window of it, at any image size) composite over it, as
NerFACE's fixed background; every other camera (an orbit, a turntable) over the avatar's background colour."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import torch

from models.avatars.components.kept import Kept
from render.camera import Camera


class Plate(Kept):
    """The background plate (H,W,3) and the camera it belongs to (camera_key); neither until a capture gives them."""

    weight_names: ClassVar[dict[str, str]] = {"image": "plate", "camera": "plate_camera"}

    def __init__(self):
        super().__init__()
        self._resized: tuple | None = None

    def note(self, image: np.ndarray, camera: Camera, device: torch.device | str = "cpu") -> None:
        """Keep the capture's plate (H,W,3) and its camera (saved with the weights)."""
        self.keep("image", torch.as_tensor(np.asarray(image, np.float32), device=device))
        self.keep("camera", torch.as_tensor(camera_key(camera), device=device))

    def for_camera(self, camera: Camera) -> torch.Tensor | None:
        """(H*W,3) the plate where `camera` sees it: the capture's camera, a frame's window of it (a following
        crop's frames each see a part of the plate), or either scaled to another image size (the studio's timeline
        renders at the size it shows: the plate resampled to it, area-averaged); else None (plate_window)."""
        if self.camera is None:
            return None
        window = plate_window(self.camera.cpu().numpy(), camera_key(camera))
        if window is None:
            return None
        x0, y0, w, h = window
        if (x0, y0, w, h) == (0, 0, *self.image.shape[1::-1]) and (w, h) == (camera.width_px, camera.height_px):
            return self.image.reshape(-1, 3)
        if (w, h) == (camera.width_px, camera.height_px):
            return self.image[y0:y0 + h, x0:x0 + w].reshape(-1, 3)
        size = (camera.width_px, camera.height_px)
        cached = self._resized
        if cached is None or cached[0] != (size, window) or cached[1] is not self.image:  # once per size and window
            import cv2

            image = cv2.resize(self.image[y0:y0 + h, x0:x0 + w].cpu().numpy(), size, interpolation=cv2.INTER_AREA)
            cached = ((size, window), self.image, torch.as_tensor(image, device=self.image.device).reshape(-1, 3))
            self._resized = cached
        return cached[2]


def plate_window(plate_key: np.ndarray, key: np.ndarray, tol_px: float = 1e-3) -> tuple[int, int, int, int] | None:
    """Where a camera's image lies in a plate's (both as camera_key gives them): (x0, y0, w, h) in the plate's
    pixels, when the camera is the plate's own, cut to a window of whole pixels and possibly scaled (its focal
    lengths sx, sy times the plate's: its pixel x is the plate's x0 + x / sx); None for any other camera (another
    view, focal ratio, or a window reaching past the plate).

    >>> plate = camera_key_of(256, 192, 500.0, 500.0, 150.0, 100.0)
    >>> plate_window(plate, camera_key_of(64, 64, 500.0, 500.0, 150.0 - 40, 100.0 - 16))  # a window at (40, 16)
    (40, 16, 64, 64)
    >>> plate_window(plate, camera_key_of(32, 32, 250.0, 250.0, 55.0, 42.0))  # that window at half the size
    (40, 16, 64, 64)
    >>> plate_window(plate, camera_key_of(64, 64, 500.0, 500.0, 150.0 - 200, 100.0)) is None  # past the plate
    True
    """
    if not np.allclose(key[6:], plate_key[6:], rtol=1e-6, atol=1e-4):
        return None
    sx, sy = key[2] / plate_key[2], key[3] / plate_key[3]
    w, h, x0, y0 = key[0] / sx, key[1] / sy, plate_key[4] - key[4] / sx, plate_key[5] - key[5] / sy
    whole = np.round([x0, y0, w, h])
    if np.abs(whole - [x0, y0, w, h]).max() > tol_px:
        return None
    x0, y0, w, h = (int(v) for v in whole)
    if x0 < 0 or y0 < 0 or w < 1 or h < 1 or x0 + w > plate_key[0] or y0 + h > plate_key[1]:
        return None
    return x0, y0, w, h


def camera_key_of(width: int, height: int, fx: float, fy: float, cx: float, cy: float,
                  view: np.ndarray | None = None) -> np.ndarray:
    """camera_key's layout from its parts (view: the identity where not given)."""
    view = np.eye(4) if view is None else view
    return np.concatenate([[width, height, fx, fy, cx, cy], np.asarray(view).ravel()]).astype(np.float64)


def camera_key(camera: Camera) -> np.ndarray:
    """(22,) float64: a camera's image size, pixel intrinsics and view matrix (which camera a plate belongs to)."""
    return camera_key_of(camera.width_px, camera.height_px, *camera.intrinsics, camera.view)
