"""Where a trained avatar's frame goes, on a capture's held-out frames as `eval` renders them: the whole frame
(`render_image` with the frame's room, eval's timing) and its parts, each timed where render_image calls it: posing
the mesh (frame_geometry), the camera's rays, the primitives' decode, their candidate lists, the march, and the
normals buffer. Medians over six held-out frames spread through the split, each rendered `--repeats` times after
one warm-up frame; the CPU's threads as torch has them.

    .venv/bin/python benchmarks/bench_frame.py AVATAR CAPTURE [--repeats 2] [--out FILE.json]

To time another checkout's code on the same avatar, put that checkout first on the path:
`PYTHONPATH=OTHER .venv/bin/python benchmarks/bench_frame.py ...` (the report names the code it ran)."""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch

import models
import models.avatars.rendering as rendering
import render.gl.raster as raster
import render.rays as rays
from models.avatars.primitives import march, native
from models.avatars.primitives.avatar import PrimitivesAvatar
from models.avatars.registry import load_avatar
from models.capture.dataset import load_split
from models.capture.frames import frame_camera, frame_room
from render.gl.context import GLContext

PARTS = (("posing", PrimitivesAvatar, "frame_geometry", ()), ("camera rays", rays, "pixel_rays", (rendering, raster)),
         ("decode", PrimitivesAvatar, "decode", ()), ("candidate lists", march, "candidate_lists", ()),
         ("march", native, "march", ()), ("normals buffer", rendering, "surface_normals", ()))
"""(name, where it is defined, what, the modules that hold it under its name too): the calls timed within a
frame (a whole head's are its inside's, a PrimitivesAvatar)."""


@contextmanager
def timed_parts(times: dict[str, list[float]]):
    """Each of PARTS' functions, wherever it is held, wrapped to add its milliseconds to times[name]; put back
    after."""
    kept = []
    for name, owner, what, holders in PARTS:
        plain = getattr(owner, what)

        @functools.wraps(plain)
        def timed(*args, _plain=plain, _name=name, **kwargs):
            t0 = time.perf_counter()
            try:
                return _plain(*args, **kwargs)
            finally:
                times[_name].append(1e3 * (time.perf_counter() - t0))

        for where in (owner, *holders):
            kept.append((where, what, getattr(where, what)))
            setattr(where, what, timed)
    try:
        yield
    finally:
        for where, what, plain in reversed(kept):
            setattr(where, what, plain)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("avatar", type=Path)
    ap.add_argument("capture", type=Path)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    avatar, _ = load_avatar(args.avatar)
    split = load_split(args.capture, "test")
    rasterizer = raster.Rasterizer(GLContext.headless())
    frames = split.frames[:: max(1, len(split.frames) // 6)][:6]

    def render(f):
        return rendering.render_image(avatar, frame_camera(split, f), f.controls, rendering.RenderOptions(
            room=frame_room(f)), rasterizer=rasterizer)

    render(frames[0])
    whole, parts = [], defaultdict(list)
    for _ in range(args.repeats):
        for f in frames:
            calls: dict[str, list[float]] = defaultdict(list)
            with timed_parts(calls):
                t0 = time.perf_counter()
                render(f)
                whole.append(1e3 * (time.perf_counter() - t0))
            for name, ms in calls.items():
                parts[name].append(sum(ms))
    report = {"avatar": str(args.avatar), "capture": str(args.capture), "code": str(Path(models.__file__).parents[1]),
              "threads": torch.get_num_threads(), "frames": len(whole), "frame_ms": round(float(np.median(whole)), 1),
              "parts_ms": {name: round(float(np.median(ms)), 1) for name, ms in parts.items()}}
    print(json.dumps(report))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
