"""A real person's avatar: its normals beside its render on held-out frames, the median angle of its normals buffer
to the tracked mesh's over the face's skin, and its opacity's edge at rest from below (as loaded, then
with what the capture's training frames saw noted again, as training notes it: the primitives' fade of
`primitives/seen.py` for an avatar trained before it).

    .venv/bin/python scripts/real_normals.py out/real/d3_view_av out/real/d3_view out/real/d3_normals

Writes OUT/normals.png (rows: truth, render, normals of a few test frames), OUT/edges.png (at rest, yaw 0/45/90,
15 degrees from below: without the fade, with it) and OUT/normals.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from app.avatar_commands import face_mask_of
from app.head_commands import save_png
from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.capture.dataset import load_split
from models.capture.frames import frame_camera, load_rgb
from models.head.controls import Controls
from models.training.metrics import normal_angles_deg
from render.camera import clipping_around, framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.normals import mesh_normal_image


def to_bytes(rgb: np.ndarray) -> np.ndarray:
    return (np.clip(rgb, 0.0, 1.0) * 255).round().astype(np.uint8)


def training_views(avatar, folder: Path, raster: Rasterizer) -> SimpleNamespace:
    """What note_views reads of the trainer's frames, from a capture's training split (no images kept)."""
    split = load_split(folder, "train")
    c2w = torch.as_tensor(np.stack([np.asarray(f.camera_to_world, np.float64) for f in split.frames]))
    return SimpleNamespace(split=split, geometry=[avatar.frame_geometry(f.controls, raster) for f in split.frames],
                           rotations=c2w[:, :3, :3], origins=c2w[:, :3, 3],
                           images=torch.empty(len(split.frames), split.height, split.width, 0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("avatar", type=Path)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--frames", type=int, default=4, help="test frames shown")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    avatar, _ = load_avatar(args.avatar)
    raster = Rasterizer(GLContext.headless())
    test = load_split(args.dataset, "test")
    rows, angles = [], []
    shown = test.frames[:: max(1, len(test.frames) // args.frames)][: args.frames]
    for f in test.frames:
        cam = frame_camera(test, f)
        out = render_image(avatar, cam, f.controls, rasterizer=raster)
        geo = avatar.frame_geometry(f.controls, raster)
        posed = geo.posed.detach().cpu().numpy()
        mesh = raster.rasterize(posed, avatar.head_model.triangles, clipping_around(cam, posed))
        skin = face_mask_of(f, out["rgb"].shape) & mesh.hit & (out["opacity"] > 0.5)
        truth_n = mesh_normal_image(mesh, posed, avatar.head_model.triangles)
        if skin.any():
            angles.append(normal_angles_deg(out["normals"], truth_n, skin))
        if f in shown:
            rows.append(np.concatenate([load_rgb(f.image_path, avatar.background_colour()), out["rgb"],
                                        out["normals"] * 0.5 + 0.5, truth_n * 0.5 + 0.5], 1))
    save_png(args.out / "normals.png", to_bytes(np.concatenate(rows, 0)))
    every = np.concatenate(angles)
    report = {"avatar": str(args.avatar), "frames": len(angles), "skin_pixels": int(every.size),
              "median_deg_to_mesh": float(np.median(every)), "mean_deg_to_mesh": float(every.mean())}
    edges = []
    for faded in (False, True):
        if faded:  # what the capture saw, noted as training notes it (an avatar trained before the fade has none)
            avatar.note_views(training_views(avatar, args.dataset, raster))
        row = []
        for yaw in (0.0, 45.0, 90.0):
            cam = framing_camera(avatar.card.rest_vertices(), yaw, -15.0, fov_y_deg=18.0, width_px=256, height_px=256,
                                 margin=1.4)
            rest = avatar.card.at_rest(Controls())
            row.append(render_image(avatar, cam, rest, RenderOptions(buffers=()), raster)["rgb"])
        edges.append(np.concatenate(row, 1))
    save_png(args.out / "edges.png", to_bytes(np.concatenate(edges, 0)))
    (args.out / "normals.json").write_text(json.dumps(report, indent=1))
    print(json.dumps(report))


if __name__ == "__main__":
    main()
