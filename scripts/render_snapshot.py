"""Every buffer of avatars rendered at fixed controls and views, saved as float arrays, and two such snapshots
compared: how a refactor proves that nothing a user sees changed.

    .venv/bin/python scripts/render_snapshot.py save out/before.npz resources/demo_avatar out/nerface_avatar
    (change the code)
    .venv/bin/python scripts/render_snapshot.py save out/after.npz resources/demo_avatar out/nerface_avatar
    .venv/bin/python scripts/render_snapshot.py compare out/before.npz out/after.npz

Per avatar: neutral and an expression with the head turned and the jaw open, two orbits (20 and -35 degrees),
the mean code and training frame 3's, 64x64, with the inspection buffers the avatar offers."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.head.controls import Controls
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer


def save(out: Path, folders: list[Path]) -> None:
    raster = Rasterizer(GLContext.headless())
    images = {}
    for folder in folders:
        avatar, _ = load_avatar(folder)
        head = avatar.head_model
        expr = np.zeros(head.num_expression, np.float32)
        expr[:3] = 0.6
        # the jaw opened by its joint where the head has one, else by its jawOpen blend shape (ICT)
        jaw = np.array([0.2, 0, 0], np.float32) if "jaw" in head.joint_names else np.zeros(3, np.float32)
        if "jaw" not in head.joint_names and "jawOpen" in head.expr_names:
            expr[head.expression_index("jawOpen")] = 0.6
        cases = [Controls(), Controls(expression=expr, root=np.array([0.1, 0.4, 0.0], np.float32), jaw=jaw)]
        for ci, controls in enumerate(cases):
            for yaw in (20.0, -35.0):
                cam = framing_camera(head.template, yaw, 5.0, fov_y_deg=18.0, width_px=64, height_px=64)
                for frame in (None, 3):
                    options = RenderOptions(frame=frame, inspect=True)
                    for k, v in render_image(avatar, cam, controls, options, raster).items():
                        images[f"{folder.name}/{ci}/{yaw}/{frame}/{k}"] = v
    np.savez(out, **images)
    print(f"wrote {out}: {len(images)} buffers")


def compare(a_path: Path, b_path: Path) -> None:
    a, b = np.load(a_path), np.load(b_path)
    worst: dict[tuple[str, str], float] = {}
    for k in sorted(set(a.files) & set(b.files)):
        x, y = a[k], b[k]
        if not np.array_equal(np.isfinite(x), np.isfinite(y)):
            raise SystemExit(f"{k}: the finite pixels differ")
        finite = np.isfinite(x)
        d = float(np.abs(x[finite] - y[finite]).max()) if finite.any() else 0.0
        key = (k.split("/")[0], k.split("/")[-1])
        worst[key] = max(worst.get(key, 0.0), d)
    for (avatar, buffer), d in sorted(worst.items()):
        print(f"{avatar:24s} {buffer:16s} max |difference| {d:.2e}")
    print(f"{len(set(a.files) & set(b.files))} buffers compared; only in one: {sorted(set(a.files) ^ set(b.files))}")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="verb", required=True)
    s = sub.add_parser("save")
    s.add_argument("out", type=Path)
    s.add_argument("avatars", type=Path, nargs="+")
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = p.parse_args()
    save(args.out, args.avatars) if args.verb == "save" else compare(args.a, args.b)
