"""A full turn of avatars at rest, as a contact sheet: one row an avatar, ANGLES columns from the front round to the
left (yaw 0, 30, ... degrees), 5 degrees above the head's centre, as `turntable --sweep-deg 0` frames them.

    .venv/bin/python scripts/turntable_sheet.py OUT.png AVATAR [AVATAR ...] [--angles 12] [--size 128]"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from app.head_commands import save_png
from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.head.controls import Controls
from render.camera import TURNTABLE_ELEVATION_DEG
from render.gl.context import GLContext
from render.gl.raster import Rasterizer


def turn(avatar, raster: Rasterizer, angles: int, size: int, elevation_deg: float = TURNTABLE_ELEVATION_DEG
         ) -> list[np.ndarray]:
    """(size,size,3) renders round the avatar at rest, from the front to its left."""
    rest = avatar.card.at_rest(Controls())
    views = []
    for k in range(angles):
        yaw = 360.0 * k / angles
        cam = avatar.card.turntable_camera(yaw, size, elevation_deg)
        views.append(np.asarray(render_image(avatar, cam, rest, RenderOptions(buffers=()), raster)["rgb"]))
    return views


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("avatars", nargs="+", type=Path)
    ap.add_argument("--angles", type=int, default=12)
    ap.add_argument("--size", type=int, default=128)
    a = ap.parse_args()
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    rows = [np.concatenate(turn(load_avatar(folder)[0], raster, a.angles, a.size), 1) for folder in a.avatars]
    save_png(a.out, (np.clip(np.concatenate(rows, 0), 0, 1) * 255).round().astype(np.uint8))
    print(f"wrote {a.out}: {len(rows)} avatars x {a.angles} angles")


if __name__ == "__main__":
    main()
