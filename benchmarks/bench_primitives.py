"""Where a primitives avatar's frame time goes, at 128, 256 and 512 pixels on this machine: the decode (once a
frame), the screen tiles' candidate lists (the whole image's, timed apart), the march as display runs it (the rays
in one group a torch thread, each group's lists and waves: slab tests, lookups and compositing) and within it the
lookups (one timed march; with groups on threads, the sum of the threads' lookup times), and the whole
`render_image` (posing the mesh, rays, images); with the lookups made and the lookups a second. Each row with the
march in C (native.py, what display runs where it is built) and in torch (the reference). Each size twice:
the colour render the studio shows first ("rgb": the grids' rgb channels alone) and with every buffer the avatar
offers ("all": its normals and the key light's visibility composited too, and the normals buffer render_image makes
from the frame's depth and the guide mesh, `normals_ms`, timed apart).

    .venv/bin/python -m benchmarks.bench_primitives AVATAR [--out benchmarks/results/primitives.json]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import torch

from benchmarks.bench_render import median_seconds
from models.avatars.checkpoint import CheckpointError
from models.avatars.primitives import march, native
from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, pixel_rays_of, render_image, surface_normals
from models.head.controls import Controls
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer


def measure(avatar, raster: Rasterizer, controls: Controls, size: int, buffers: tuple[str, ...] | None,
            in_c: bool) -> dict:
    """One size's row: the parts' median times and the lookups, making `buffers` (render_image's: () the colour
    alone, None every buffer), the march in C (native.py) or in torch (its lookups timed apart)."""
    os.environ["AVATAR_STUDIO_NATIVE"] = "1" if in_c else "0"
    cam = framing_camera(avatar.card.rest_vertices(), 0.0, 0.0, fov_y_deg=18.0, width_px=size, height_px=size)
    geo = avatar.frame_geometry(controls, raster)
    rays, _ = pixel_rays_of(avatar, geo, cam, raster)
    eye = rays.origins[0]
    options = RenderOptions(buffers=buffers)  # the decode and the march make those buffers alone
    extras = avatar.shown_channels(options=options)
    with torch.inference_mode():
        code = avatar.codes(None, geo.code_weights)
        decode = median_seconds(lambda: avatar.decode(geo, code, eye, extras=extras))
        prims, _ = avatar.decode(geo, code, eye, extras=extras)
        lists_s = median_seconds(lambda: march.candidate_lists(rays.origins, rays.directions, prims))
        lists = march.candidate_lists(rays.origins, rays.directions, prims)
        bg = avatar.ray_background(rays)

        def run():
            return avatar.display_march(rays.origins, rays.directions, bg, prims, options)

        march_s = median_seconds(run)
        looked = []  # the lookups' share of one march: march.lookup timed where the march calls it
        plain = march.lookup

        def timed(*args):
            t0 = time.perf_counter()
            v = plain(*args)
            looked.append(time.perf_counter() - t0)
            return v

        march.lookup = timed
        try:
            out = run()
        finally:
            march.lookup = plain
    whole = median_seconds(lambda: render_image(avatar, cam, controls, RenderOptions(buffers=buffers), raster))
    normals = None
    if buffers is None and avatar.normals_from_surface:  # the rendered surface's normals (render/normals.py)
        depth = render_image(avatar, cam, controls, RenderOptions(buffers=()), raster)["depth"]
        normals = median_seconds(lambda: surface_normals(avatar, depth, geo, cam, raster))
    return {"size": size, "buffers": "all" if buffers is None else "rgb", "march": "C" if in_c else "torch",
            "channels": prims.colour.shape[-1],
            "rays": len(rays), "decode_ms": 1e3 * decode, "lists_ms": 1e3 * lists_s,
            "march_ms": 1e3 * march_s, "lookup_ms": None if in_c else 1e3 * sum(looked),
            "normals_ms": None if normals is None else 1e3 * normals, "render_image_ms": 1e3 * whole,
            "candidates": lists.pairs, "segments": out.segments, "lookups": out.samples,
            "lookups_per_s": out.samples / march_s}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("avatar", type=Path)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/primitives.json"))
    p.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512])
    args = p.parse_args()
    try:
        avatar, _ = load_avatar(args.avatar, model="primitives")
    except CheckpointError as e:
        raise SystemExit(str(e)) from None
    raster = Rasterizer(GLContext.headless())
    controls = avatar.card.at_rest(Controls())
    rows = []
    marches = (True, False) if native.library() is not None else (False,)
    if not marches[0]:
        print(f"the C march is not built ({native.failure() or 'AVATAR_STUDIO_NATIVE=0'}): torch's alone")
    for size in args.sizes:
        for buffers in ((), None):
            for in_c in marches:
                rows.append(measure(avatar, raster, controls, size, buffers, in_c))
                print(json.dumps({k: round(v, 1) if isinstance(v, float) else v for k, v in rows[-1].items()}))
    report = {"avatar": str(args.avatar), "primitives": avatar.count, "voxels": avatar.cfg.voxels,
              "samples": avatar.cfg.samples, "threads": torch.get_num_threads(), "cpus": os.cpu_count(), "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
