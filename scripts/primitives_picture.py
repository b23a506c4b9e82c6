"""A primitives avatar's render beside the same render with its primitives' boxes drawn over it (those facing the
camera), so one sees where the volume lives and how big each piece is.

    .venv/bin/python scripts/primitives_picture.py AVATAR --out out/primitives.png [--size 256] [--yaw 20]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.head_commands import save_png
from models.avatars.checkpoint import CheckpointError
from models.avatars.primitives import march
from models.avatars.registry import load_avatar
from models.avatars.rendering import render_image
from models.head.controls import Controls
from render.camera import Camera, framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]  # one sign apart


def project(camera: Camera, points: np.ndarray) -> np.ndarray:
    """(N,2) pixel positions (x right, y down) of world points (N,3) in front of the camera."""
    fx, fy, cx, cy = camera.intrinsics
    p = points @ camera.view[:3, :3].T + camera.view[:3, 3]
    z = np.maximum(-p[:, 2], 1e-6)
    return np.stack([cx + fx * p[:, 0] / z, cy - fy * p[:, 1] / z], 1)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("avatar", type=Path)
    ap.add_argument("--out", type=Path, default=Path("out/primitives.png"))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--yaw", type=float, default=20.0)
    args = ap.parse_args()
    try:
        avatar, _ = load_avatar(args.avatar, model="primitives")
    except CheckpointError as e:
        print(e, file=sys.stderr)
        return 2
    controls = avatar.card.at_rest(Controls())
    cam = framing_camera(avatar.card.rest_vertices(), args.yaw, 5.0, fov_y_deg=18.0, width_px=args.size,
                         height_px=args.size)
    raster = Rasterizer(GLContext.headless())
    image = render_image(avatar, cam, controls, rasterizer=raster)["rgb"]
    geo = avatar.frame_geometry(controls, raster)
    with torch.inference_mode():
        prims, _ = avatar.decode(geo, avatar.codes(None, geo.code_weights),
                                 torch.as_tensor(cam.position, dtype=torch.float32))
    corners = march.box_corners(prims).numpy()
    facing = (prims.rotations[:, :, 2].numpy() * (cam.position - prims.centres.numpy())).sum(1) > 0
    drawn = (np.clip(image, 0, 1) * 255).astype(np.uint8).copy()
    scale = 4  # lines drawn at 4x and scaled down: antialiased
    big = cv2.resize(drawn, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    for k in np.nonzero(facing)[0]:
        px = project(cam, corners[k]) * scale
        for a, b in EDGES:
            cv2.line(big, tuple(int(v) for v in px[a]), tuple(int(v) for v in px[b]), (255, 200, 0), 1, cv2.LINE_AA)
    drawn = cv2.resize(big, (args.size, args.size), interpolation=cv2.INTER_AREA)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_png(args.out, np.concatenate([(np.clip(image, 0, 1) * 255).astype(np.uint8), drawn], 1))
    print(f"wrote {args.out}: {int(facing.sum())} of {len(prims)} primitives face the camera")
    return 0


if __name__ == "__main__":
    sys.exit(main())
