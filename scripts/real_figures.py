"""The figures of a real-video avatar for the README's table: its held-out metrics (from `eval`), training steps,
and render times on this machine at the capture's size and at 128 px (the median of the first and last held-out
frames, three renders each); for CoDyNeRF also with the 3 cm shell that the masks' sampler replaced (what modelling
hair and collar costs).

    .venv/bin/python scripts/real_figures.py out/real/256/expressions_d3/none out/real/256/expressions_d3/dataset
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from models.avatars.registry import load_avatar
from models.avatars.rendering import render_image
from models.capture.dataset import load_split
from models.capture.frames import frame_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer


def median_ms(avatar, frames, split, raster, size: int | None = None, repeats: int = 1) -> float:
    times = []
    for f in frames:
        cam = frame_camera(split, f)
        cam = cam if size is None else cam.resized(size, size)
        for _ in range(repeats):
            t0 = time.perf_counter()
            render_image(avatar, cam, f.controls, rasterizer=raster)
            times.append(1e3 * (time.perf_counter() - t0))
    return float(np.median(times))


def main() -> None:
    folder, dataset = Path(sys.argv[1]), Path(sys.argv[2])
    torch.set_num_threads(2)
    avatar, meta = load_avatar(folder)
    metrics = json.loads((folder / "eval" / "metrics.json").read_text())["metrics"]
    split = load_split(dataset, "test")
    frames = [split.frames[0], split.frames[-1]]
    raster = Rasterizer(GLContext.headless())
    out = {"model": meta.get("model"), "psnr": round(metrics["psnr"], 2), "ssim": round(metrics["ssim"], 3),
           "face_mse": round(metrics["face_mse"], 4), "steps": meta["provenance"]["steps"],
           "minutes": round(meta["provenance"]["seconds"] / 60, 1),
           "ms": round(median_ms(avatar, frames, split, raster, repeats=3)),
           "ms_128": round(median_ms(avatar, frames, split, raster, 128, repeats=3))}
    rc = getattr(avatar, "render_cfg", None)
    if rc is not None and hasattr(rc, "shell_m"):  # a field sampled in a shell (CoDyNeRF): the 3 cm shell's cost
        out |= {"shell_m": round(rc.shell_m, 3), "samples": rc.samples_per_ray}
        avatar.render_cfg = replace(rc, shell_m=0.03, box_margin_m=0.03, samples_per_ray=12,
                                    silhouette_m=min(rc.silhouette_m or 0.03, 0.03))
        out["ms_3cm_shell"] = round(median_ms(avatar, frames, split, raster))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
