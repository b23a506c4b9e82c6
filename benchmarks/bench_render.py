"""Render time of trained avatars at 64, 128 and 256 pixels (default display settings), and of the NerFACE
baseline's dense renderer (8x256 MLPs, 64 coarse + 64 fine samples on every ray that crosses the head's box)
at 128 pixels, on this machine.

    .venv/bin/python -m benchmarks.bench_render AVATAR [AVATAR ...] [--out benchmarks/results/render.json]

A NerFACE avatar among the AVATARs is timed at 128 px only (about half a minute a frame); without one, an
untrained NerFACE of the published size is timed (its weights do not change the work).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from models.avatars.registry import BASELINE_MODEL, load_avatar, untrained_avatar
from models.avatars.rendering import render_image
from models.head.controls import Controls
from models.head.sources import load_head
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer


def median_seconds(fn, repeats: int = 5) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("avatars", nargs="+", type=Path)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/render.json"))
    a = p.parse_args()
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    results: dict = {"threads": torch.get_num_threads(), "avatar_ms": {}}
    nerface = None
    for path in a.avatars:
        avatar, meta = load_avatar(path)
        if not avatar.quality_knobs:  # a dense baseline (no render settings): timed once, at 128 px
            nerface = avatar
            continue
        name = "+".join(meta["effects"]) or "none"
        for size in (64, 128, 256):
            cam = framing_camera(avatar.head_model.template, 20, 5, fov_y_deg=18.0, width_px=size, height_px=size)
            s = median_seconds(lambda cam=cam, av=avatar: render_image(av, cam, Controls(), rasterizer=raster))
            results["avatar_ms"][f"{name} {size}px"] = round(1e3 * s, 1)
            print(f"avatar {name:24s} {size:4d} px: {1e3 * s:8.1f} ms", flush=True)
    if nerface is None:
        head = load_head(meta["head_model"])
        nerface = untrained_avatar(BASELINE_MODEL, head)
    cam = framing_camera(nerface.head_model.template, 20, 5, fov_y_deg=18.0, width_px=128, height_px=128)
    s = median_seconds(lambda: render_image(nerface, cam, Controls(), rasterizer=raster), repeats=1)
    results["nerface_dense_128px_ms"] = round(1e3 * s, 1)
    print(f"NerFACE dense renderer 128 px: {s:.1f} s")
    for key, ms in results["avatar_ms"].items():
        if key.endswith(" 128px"):
            results[f"nerface_over_{key.split()[0]}_128px"] = round(1e3 * s / ms, 1)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
