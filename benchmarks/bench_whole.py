"""What a whole head (models/avatars/whole/) costs to render against its parts: a 256 px frame at rest from the
front round to behind (yaw 0, 30, 60, 90, 135, 180 degrees, as turntables frame it), the median of 3 renders on one
thread (the studio's renderer has one), for the whole head, its inside (the primitives from scratch) and its
outside (the personalised prior); and the share of the frame's rays each part renders.

    .venv/bin/python -m benchmarks.bench_whole AVATAR [AVATAR ...] [--size 256] [--out benchmarks/results/whole.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, pixel_rays_of, render_image
from models.head.controls import Controls
from render.camera import turntable_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

YAWS = (0, 30, 60, 90, 135, 180)


def median_ms(avatar, camera, controls, raster, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        render_image(avatar, camera, controls, RenderOptions(buffers=()), raster)
        times.append(1e3 * (time.perf_counter() - t0))
    return round(float(np.median(times)), 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("avatars", nargs="+", type=Path)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/whole.json"))
    a = ap.parse_args()
    torch.set_num_threads(1)
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    rows = []
    for folder in a.avatars:
        whole, _ = load_avatar(folder, model="whole")
        rest = whole.card.at_rest(Controls())
        for yaw in YAWS:
            cam = turntable_camera(whole.card.rest_vertices(), float(yaw), 5.0, fov_y_deg=18.0, width_px=a.size,
                                   height_px=a.size)
            geo = whole.frame_geometry(rest, raster)
            rays, _ = pixel_rays_of(whole, geo, cam, raster)
            with torch.inference_mode():
                w = whole.inside_weight(rays, geo)
            row = {"avatar": str(folder), "yaw_deg": yaw, "rays": len(w),
                   "inside_share": round(float((w > 1e-3).float().mean()), 3),
                   "outside_share": round(float((w < 1 - 1e-3).float().mean()), 3),
                   "whole_ms": median_ms(whole, cam, rest, raster),
                   "inside_ms": median_ms(whole.inside, cam, rest, raster),
                   "outside_ms": median_ms(whole.outside, cam, rest, raster)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps({"size_px": a.size, "threads": 1, "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
