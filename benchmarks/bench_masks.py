"""How true `track`'s masks are: MediaPipe's selfie segmenter against GrabCut (models/tracking/masks.py), by
intersection over union with masks known to be true, and the time each takes.

The truths:
- three real clips filmed before a plain backdrop (a green screen, a blue wall, a grey wall: TRUTHS), 6 frames of
  each spread over the clip and cropped about the face as `track` crops: the person is every pixel far from the
  backdrop's colour (CIELAB distance to the median of the crop's top corners; the piece holding the face, holes
  filled). Each of these masks was checked by eye (`--check DIR` writes them over their frames); the frames where
  the key was wrong are left out (TRUTHS);
- a synthetic capture (`avatar-studio synth`), whose masks are the renderer's. Its bust ends in the air above the
  frame's bottom, which no filmed person does: the segmenter, made for people, carries the body on down.
GrabCut is seeded by the face's landmarks (MediaPipe's, found in each image) as `track` seeds it.

    .venv/bin/avatar-studio synth --head demo --scene sun --frames 40 --size 256 --out out/masks_synth
    .venv/bin/python -m benchmarks.bench_masks --synthetic out/masks_synth [--check out/mask_truths]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np

from models.tracking.landmarker import Landmarker, packaged_bundle
from models.tracking.masks import foreground_mask
from models.tracking.segmenter import PersonSegmenter, fill_holes, installed_model

VIDEOS = Path(__file__).resolve().parents[2] / "shared" / "data" / "video"
TRUTHS = {"more/grimaces_green_screen": (30.0, ()), "more/woman_blue_wall": (30.0, ()),
          "more/talking_earrings": (25.0, (5,))}
"""Clip: (the key's CIELAB distance, the frames (of 6) whose key was wrong by eye: left out). talking_earrings' 6th
frame: the wall lighter at its left edge, taken for the person."""
FRAMES = 6
def video_frames(path: Path, count: int) -> list[np.ndarray]:
    """`count` RGB frames spread evenly over a video."""
    cap = cv2.VideoCapture(str(path))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    frames = []
    for k in np.linspace(0, max(n - 1, 0), count).round().astype(int):
        cap.set(cv2.CAP_PROP_POS_FRAMES, int(k))
        ok, bgr = cap.read()
        if ok:
            frames.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    cap.release()
    return frames


def backdrop_key(rgb: np.ndarray, face_px: np.ndarray, distance: float) -> np.ndarray:
    """(H,W) bool: the person before a plain backdrop: pixels whose CIELAB colour is over `distance` from the
    backdrop's (the median of the image's top corners, a sixth of its height by an eighth of its width), opened
    over 3 px, the piece holding the face (its landmarks (N,2)), holes filled.

    >>> img = np.zeros((48, 48, 3), np.uint8); img[...] = (60, 160, 100); img[12:40, 16:32] = (200, 150, 130)
    >>> int(backdrop_key(img, np.array([[20.0, 20.0], [24.0, 30.0]]), 30.0).sum())  # the 28 x 16 person
    448
    """
    lab = cv2.cvtColor(rgb, cv2.COLOR_RGB2LAB).astype(np.float32)
    h, w = rgb.shape[:2]
    corners = np.concatenate([lab[: h // 6, : w // 8].reshape(-1, 3), lab[: h // 6, -(w // 8):].reshape(-1, 3)])
    person = (np.linalg.norm(lab - np.median(corners, 0), axis=-1) > distance).astype(np.uint8)
    person = cv2.morphologyEx(person, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    _, labels = cv2.connectedComponents(person)
    cx, cy = np.round(face_px.mean(0)).astype(int)
    return fill_holes((labels == labels[cy, cx]).astype(np.uint8) * person).astype(bool)


def square_about(rgb: np.ndarray, face_px: np.ndarray, size: int, widths: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """A square crop of the frame about the face (`widths` face widths across, the frame's shorter side at most),
    resized to `size`; and the face's landmarks in it."""
    h, w = rgb.shape[:2]
    lo, hi = face_px.min(0), face_px.max(0)
    side = int(min(min(h, w), widths * (hi - lo).max()))
    cx, cy = (lo + hi) / 2
    x0 = int(np.clip(cx - side / 2, 0, w - side))
    y0 = int(np.clip(cy - side / 2 + 0.1 * side, 0, h - side))  # a little lower: the shoulders
    crop = cv2.resize(rgb[y0:y0 + side, x0:x0 + side], (size, size), interpolation=cv2.INTER_AREA)
    return crop, (face_px - [x0, y0]) * (size / side)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def faces_of(frames: list[np.ndarray], landmarker: Landmarker) -> list[np.ndarray | None]:
    found = []
    for k, f in enumerate(frames):
        faces = landmarker.detect(f, 33 * k)
        found.append(faces[0].landmarks_px[:468] if faces else None)
    return found


def score(cases: list[tuple[np.ndarray, np.ndarray, np.ndarray]], segmenter: PersonSegmenter) -> dict:
    """IoU with the truth and ms a frame over cases (crop, landmarks in it, true mask) of each of `track`'s ways:
    the selfie segmenter, and GrabCut seeded by the face."""
    ways = {"selfie": segmenter.mask, "grabcut": foreground_mask}
    out = {}
    for way, cut in ways.items():
        ious, ms = [], []
        for crop, points, truth in cases:
            t0 = time.perf_counter()
            mask = cut(crop, points)
            ms.append(1e3 * (time.perf_counter() - t0))
            ious.append(iou(mask > 0.5, truth))
        out[way] = {"iou_median": round(float(np.median(ious)), 4), "iou_mean": round(float(np.mean(ious)), 4),
                    "iou_worst": round(float(np.min(ious)), 4), "ms_median": round(float(np.median(ms)), 1)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--synthetic", type=Path, help="a synthetic capture (avatar-studio synth): its images and masks")
    ap.add_argument("--check", type=Path, help="write each real truth over its frame here, to check by eye")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/masks.json"))
    args = ap.parse_args()
    model = installed_model()
    if model is None or not VIDEOS.is_dir():
        raise SystemExit("needs the selfie segmenter's model (make setup) and ../shared/data/video")
    segmenter = PersonSegmenter(model)
    truths = {}
    with Landmarker(packaged_bundle(), max_faces=1, video=False) as landmarker:
        for clip, (distance, wrong) in TRUTHS.items():
            frames = video_frames(VIDEOS / f"{clip}.mp4", FRAMES)
            cases = []
            for k, (frame, face) in enumerate(zip(frames, faces_of(frames, landmarker), strict=True)):
                if face is not None and k not in wrong:
                    crop, points = square_about(frame, face, args.size)
                    cases.append((crop, points, backdrop_key(crop, points, distance)))
            truths[clip] = cases
        if args.synthetic is not None:
            cases = []
            for path in sorted((args.synthetic / "images").glob("*.png")):
                rgb = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
                face = faces_of([rgb], landmarker)[0]
                if face is not None:
                    cases.append((rgb, face, cv2.imread(str(args.synthetic / "masks" / path.name), 0) > 127))
            truths[f"synthetic ({args.synthetic})"] = cases
    if args.check is not None:
        args.check.mkdir(parents=True, exist_ok=True)
        for clip in TRUTHS:
            shown = [np.where(truth[..., None], crop, crop // 4) for crop, _, truth in truths[clip]]
            cv2.imwrite(str(args.check / f"{Path(clip).name}.png"), cv2.cvtColor(np.concatenate(shown, 1),
                                                                               cv2.COLOR_RGB2BGR))
    results = {"size_px": args.size, "truths": {}}
    for name, cases in truths.items():
        results["truths"][name] = {"frames": len(cases), **score(cases, segmenter)}
        print(name, results["truths"][name], flush=True)
    segmenter.close()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
