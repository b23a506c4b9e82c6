"""What a whole head (models/avatars/whole/) costs to render against its parts: a 256 px frame at rest from the
front round to behind (yaw 0, 30, 60, 90, 135, 180 degrees, as turntables frame it), the median of 3 renders on one
thread (the studio's renderer has one), for the whole head, its inside (the primitives from scratch) and its
outside (the personalised prior); and the share of the frame's rays each part renders.

    .venv/bin/python -m benchmarks.bench_whole AVATAR [AVATAR ...] [--size 256] [--out benchmarks/results/whole.json]

Two more measures, each also written to --out:
    --outside-settings: the outside alone from 20, 90 and 160 degrees, at rest, at its own samples and at fewer,
        each ray stopped once less than 1e-3, 1e-2 or 3e-2 of its light gets through (the whole head's
        OUTSIDE_STOP_BELOW): the median time and the PSNR against 16 samples marched to 1e-4.
    --poses CAPTURE: the whole head in the studio's default view (View()) posed by every twelfth training frame
        of a tracked capture (as live driving poses it), on the studio renderer's two cores: the median time with
        the outside decoded on a thread of its own beside the inside (WholeHeadAvatar.decode_ahead) and without.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from app.sliders import View
from models.avatars.quality import Quality
from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, pixel_rays_of, render_image
from models.capture.dataset import load_split
from models.head.controls import Controls
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

YAWS = (0, 30, 60, 90, 135, 180)


def median_ms(avatar, camera, controls, raster, repeats: int = 3, options: RenderOptions | None = None) -> float:
    options = options or RenderOptions(buffers=())
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        render_image(avatar, camera, controls, options, raster)
        times.append(1e3 * (time.perf_counter() - t0))
    return round(float(np.median(times)), 1)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return round(float(10 * np.log10(1.0 / max(float(np.mean((a.astype(np.float64) - b) ** 2)), 1e-20))), 2)


def outside_settings(whole, raster, size: int) -> list[dict]:
    """The outside's samples and early stop against its reference (module docstring)."""
    outside, own = whole.outside, whole.outside.cfg
    rest = whole.card.at_rest(Controls())
    cams = [View(yaw_deg=yaw).camera(whole.card.rest_vertices(), size, size) for yaw in (20.0, 90.0, 160.0)]

    def frames(samples: int, stop: float) -> tuple[list[np.ndarray], float]:
        outside.cfg = replace(own, stop_below=stop)
        options = RenderOptions(buffers=(), quality=Quality(1.0, samples), cores=1)
        images = [render_image(outside, cam, rest, options, raster)["rgb"] for cam in cams]
        return images, float(np.median([median_ms(outside, cam, rest, raster, options=options) for cam in cams]))

    try:
        truth, truth_ms = frames(16, 1e-4)
        rows = [{"samples": 16, "stop_below": 1e-4, "ms": round(truth_ms, 1), "psnr_db": None}]
        for samples in sorted({own.samples, 6}, reverse=True):
            for stop in (1e-3, 1e-2, 3e-2):
                images, ms = frames(samples, stop)
                rows.append({"samples": samples, "stop_below": stop, "ms": round(ms, 1),
                             "psnr_db": min(psnr(a, b) for a, b in zip(images, truth, strict=True))})
                print(json.dumps(rows[-1]), flush=True)
    finally:
        outside.cfg = own
    return rows


def posed_times(whole, raster, capture: Path, size: int) -> dict:
    """The whole head posed by a capture's frames in the studio's view, with and without the outside ahead."""
    split = load_split(capture, "train")
    rest = whole.card.at_rest(Controls())
    poses = [replace(rest, expression=f.controls.expression, root=f.controls.root, neck=f.controls.neck,
                     jaw=f.controls.jaw) for f in split.frames[::12]]
    cam = View().camera(whole.card.rest_vertices(), size, size)
    options = RenderOptions(buffers=(), quality=whole.card.presets["final"].quality, cores=2)
    out = {"capture": str(capture), "poses": len(poses)}
    for _ in range(2):  # in turn, twice: the machine's state shared alike
        for ahead in (True, False):
            whole.decode_ahead = ahead
            times = []
            for c in poses:
                t0 = time.perf_counter()
                render_image(whole, cam, c, options, raster)
                times.append(1e3 * (time.perf_counter() - t0))
            out.setdefault("ahead_ms" if ahead else "after_ms", []).append(round(float(np.median(times)), 1))
    whole.decode_ahead = True
    print(json.dumps(out), flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("avatars", nargs="+", type=Path)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/whole.json"))
    ap.add_argument("--outside-settings", action="store_true", help="the outside's samples and early stop (only)")
    ap.add_argument("--poses", type=Path, help="a tracked capture whose poses drive the whole head (only)")
    a = ap.parse_args()
    torch.set_num_threads(1)
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    if a.outside_settings or a.poses:
        found = {}
        for folder in a.avatars:
            whole, _ = load_avatar(folder, model="whole")
            found[str(folder)] = {**({"outside_settings": outside_settings(whole, raster, a.size)}
                                     if a.outside_settings else {}),
                                  **({"posed": posed_times(whole, raster, a.poses, a.size)} if a.poses else {})}
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps({"size_px": a.size, "avatars": found}, indent=1) + "\n")
        return
    rows = []
    for folder in a.avatars:
        whole, _ = load_avatar(folder, model="whole")
        rest = whole.card.at_rest(Controls())
        for yaw in YAWS:
            cam = whole.card.turntable_camera(float(yaw), a.size)
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
