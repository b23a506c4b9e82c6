"""How much of a face two framings of one video keep: each held-out frame's face box (the following crop's
dataset's bbox) cut from both avatars' renders (eval's side-by-side images) on the finer framing's pixel grid
(the coarser render resampled bicubically to it) and compared with the finer framing's ground truth: PSNR over
the face boxes of every held-out frame.

    .venv/bin/python scripts/face_detail.py out/walk/auto out/walk/av_auto/eval out/walk/fixed out/walk/av_fixed/eval
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from models.capture.dataset import load_split


def source_box(dataset: Path, k: int, split) -> tuple[np.ndarray, float, np.ndarray]:
    """Frame k's image origin in the video's pixels, the video's pixels a dataset pixel, and its bbox (pixels)."""
    crop = json.loads((dataset / "transforms_test.json").read_text())["source"]["crop"]
    f = split.frames[k]
    size = split.width
    per_px = crop["side"] / size
    _, _, cx, cy = split.frame_intrinsics(f)
    pcx, pcy = (split.background_intrinsics or split.intrinsics)[2:]
    origin = np.array([crop["x0"] + (pcx - cx) * per_px, crop["y0"] + (pcy - cy) * per_px])
    top, bottom, left, right = f.bbox
    return origin, per_px, np.array([left, top, right, bottom]) * size


def panels(path: Path) -> tuple[np.ndarray, np.ndarray]:
    img = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB).astype(np.float64) / 255.0
    s = img.shape[0]
    return img[:, :s], img[:, s:2 * s]  # ground truth, render


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("fine", type=Path)
    p.add_argument("fine_eval", type=Path)
    p.add_argument("coarse", type=Path)
    p.add_argument("coarse_eval", type=Path)
    a = p.parse_args()
    fine, coarse = load_split(a.fine, "test"), load_split(a.coarse, "test")
    errors = {"fine": [], "coarse": []}
    for k in range(len(fine.frames)):
        origin_f, px_f, box = source_box(a.fine, k, fine)
        origin_c, px_c, _ = source_box(a.coarse, k, coarse)
        x0, y0, x1, y1 = np.round(box).astype(int)
        truth, render = panels(a.fine_eval / f"test_{k:04d}.png")
        errors["fine"].append((render[y0:y1, x0:x1] - truth[y0:y1, x0:x1]) ** 2)
        _, render_c = panels(a.coarse_eval / f"test_{k:04d}.png")
        # fine pixel (u, v) -> video (origin_f + (u + 0.5) px_f) -> coarse pixel centre coordinates
        scale = px_f / px_c
        shift = (origin_f - origin_c) / px_c + 0.5 * scale - 0.5
        m = np.array([[scale, 0.0, shift[0] + x0 * scale], [0.0, scale, shift[1] + y0 * scale]])
        resampled = cv2.warpAffine(render_c, m, (x1 - x0, y1 - y0), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
        errors["coarse"].append((resampled - truth[y0:y1, x0:x1]) ** 2)
    for name, errs in errors.items():
        mse = np.mean(np.concatenate([e.reshape(-1, 3) for e in errs]))
        print(f"{name}: face-box PSNR {10 * np.log10(1 / mse):.2f} dB over {len(errs)} frames")


if __name__ == "__main__":
    main()
