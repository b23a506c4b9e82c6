"""A real person's avatar where no frame of the video looked: the sides and back of its turntable at rest, and how
many edges they show (models/training/metrics.py `edge_density`: Canny's edge pixels per 1000 of the figure's, its
outline left out). A real capture has no truth there; a patchwork of the primitives' boxes in hair and skin colours
shows as many edges, smooth hair as few. The person as the video shows them (the training frames within their masks,
a few of them) gives the figure of a real head's own detail, from the front.

    .venv/bin/python -m benchmarks.bench_sides NAME=AVATAR [NAME=AVATAR ...] [--capture CAPTURE] \\
        [--sheet sides.png] --out benchmarks/results/sides.json

A whole head is rendered as the studio shows it (its outside beyond the views); NAME=AVATAR:outside or :inside
renders one part alone.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.capture.dataset import load_split
from models.capture.frames import load_mask, load_rgb
from models.head.controls import Controls
from models.training.metrics import edge_density
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

ANGLES_DEG = (45, 90, 135, 180, 225, 270, 315)
"""Yaw round the head from the front (to its left from 0 up to 180): where a frontal video never looked."""


def sides(avatar, shown, raster: Rasterizer, angles=ANGLES_DEG, size: int = 256) -> tuple[dict, list[np.ndarray]]:
    """Edge density of `shown` (the avatar or one of its parts) at rest from each yaw, 5 degrees above the head's
    centre as `turntable --sweep-deg 0` frames it, and the renders."""
    rest = avatar.card.at_rest(Controls())
    by, renders = {}, []
    for yaw in angles:
        cam = avatar.card.turntable_camera(float(yaw), size)
        with torch.inference_mode():
            out = render_image(shown, cam, rest, RenderOptions(buffers=()), raster)
        rgb = np.asarray(out["rgb"])
        by[str(yaw)] = round(edge_density(rgb, np.asarray(out["opacity"]).reshape(rgb.shape[:2])), 1)
        renders.append(rgb)
    return by, renders


def as_filmed(capture: Path, frames: int = 8) -> float:
    """The mean edge density of `frames` training frames spread through the capture, within their masks."""
    split = load_split(capture, "train")
    picked = [split.frames[k] for k in np.linspace(0, len(split.frames) - 1, frames).round().astype(int)]
    values = []
    for f in picked:
        if "mask_path" not in f.extra:
            raise SystemExit(f"{capture}: its frames have no masks (a tracked video's have)")
        values.append(edge_density(load_rgb(f.image_path), load_mask(f.extra["mask_path"])))
    return round(float(np.mean(values)), 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("avatars", nargs="+", help="NAME=AVATAR_FOLDER[:inside|:outside]")
    ap.add_argument("--capture", type=Path, help="the avatars' capture: the person as filmed, for reference")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--sheet", type=Path, help="a PNG of the renders, one row an avatar")
    ap.add_argument("--out", type=Path, required=True, help="results JSON")
    args = ap.parse_args()
    raster = Rasterizer(GLContext.headless())
    results: dict = {"angles_deg": list(ANGLES_DEG), "size_px": args.size, "avatars": {}}
    if args.capture is not None:
        results["capture"] = str(args.capture)
        results["as_filmed"] = as_filmed(args.capture)
        print("as filmed", results["as_filmed"], flush=True)
    rows = []
    for item in args.avatars:
        name, folder = item.split("=", 1)
        folder, _, part = folder.partition(":")
        avatar, meta = load_avatar(folder)
        by, renders = sides(avatar, getattr(avatar, part) if part else avatar, raster, size=args.size)
        mean = round(float(np.mean(list(by.values()))), 1)
        results["avatars"][name] = {"folder": folder, "part": part or None, "steps": meta.get("step"),
                                    "edges_by_angle": by, "edges_mean": mean}
        rows.append(np.concatenate(renders, 1))
        print(name, by, "mean", mean, flush=True)
    if args.sheet is not None:
        from app.head_commands import save_png

        save_png(args.sheet, (np.clip(np.concatenate(rows, 0), 0, 1) * 255).round().astype(np.uint8))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
