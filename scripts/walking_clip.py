"""A clip whose subject walks across a room, for trying `track`'s following crop on real footage: the person of a
tracked clip (its frames and masks, the crop being the whole frame) cut out and laid over a still room as they
step WALK_PX across it, left to right, the room's texture everywhere (a plate that is wrong anywhere shows).
Writes the clip to OUT (it holds the source clip's pixels: keep it out of the repository).

    .venv/bin/python scripts/walking_clip.py out/real/256/expressions_d19/dataset \\
        ../shared/data/video/expressions_d19.mp4 out/walk/d19_walk.mp4 [--room 1280 720] [--scale 0.8] [--walk-px 300]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from models.tracking.video import sampled_frames
from render.video import write_video


def room(width: int, height: int, seed: int = 0) -> np.ndarray:
    """A wall of soft blotches and a floor's darker band: smooth noise at several scales, uint8 RGB."""
    rng = np.random.default_rng(seed)
    out = np.zeros((height, width, 3), np.float32)
    for cells, weight in ((4, 60.0), (12, 30.0), (40, 12.0)):
        noise = rng.random((cells * height // width + 1, cells + 1, 3)).astype(np.float32)
        out += weight * cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    out += np.array([70.0, 80.0, 95.0], np.float32)
    out[int(0.8 * height):] *= 0.7
    return out.clip(0, 255).astype(np.uint8)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", type=Path, help="the clip tracked with a crop that is its whole frame")
    p.add_argument("video", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--room", type=int, nargs=2, default=(1280, 720))
    p.add_argument("--scale", type=float, default=0.8)
    p.add_argument("--walk-px", type=int, default=300)
    a = p.parse_args()
    report = json.loads((a.dataset / "tracking" / "report.json").read_text())
    if not report["crop"]["whole_frame"]:
        raise SystemExit(f"{a.dataset}: its crop is not the whole frame; the masks would not line up")
    frames, fps = {}, 25.0
    for name in ("train", "val", "test"):
        data = json.loads((a.dataset / f"transforms_{name}.json").read_text())
        fps = data["source"]["fps"]
        for f in data["frames"]:
            frames[f["source_frame"]] = a.dataset / f["mask_path"]
    w, h = a.room
    wall = room(w, h).astype(np.float32)
    out: list[np.ndarray] = []
    for index, _, rgb in sampled_frames(a.video, None):
        if index not in frames:
            continue
        k = len(out)
        side = round(a.scale * min(rgb.shape[:2]))
        person = cv2.resize(rgb, (side, side), interpolation=cv2.INTER_AREA).astype(np.float32)
        mask = cv2.imread(str(frames[index]), cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255.0
        mask = cv2.GaussianBlur(cv2.resize(mask, (side, side), interpolation=cv2.INTER_LINEAR), (5, 5), 0)[..., None]
        x = round((w - side - a.walk_px) / 2 + a.walk_px * k / max(1, len(frames) - 1))
        frame = wall.copy()
        frame[h - side:, x:x + side] = mask * person + (1 - mask) * frame[h - side:, x:x + side]
        out.append(frame.round().clip(0, 255).astype(np.uint8))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    write_video(out, a.out, fps=fps)
    print(f"wrote {a.out}: {len(out)} frames of {w}x{h}, the person {side} px, walking {a.walk_px} px")


if __name__ == "__main__":
    main()
