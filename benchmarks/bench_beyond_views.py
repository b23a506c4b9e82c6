"""Avatars beyond the views their capture saw: each one rendered on a capture of the same person from cameras all round
(`synth --views 8`) and scored against the truth by how far the camera is from where the face looks (0, 45, 90, 135,
180 degrees, each +-22.5), so a capture that saw only the front (`synth --turn-deg 20`) can be judged from the
side and behind.

    S=out/beyond; P=1000
    avatar-studio synth --identity $P --frames 60 --size 128 --scene ambient --turn-deg 20 --out $S/front$P
    avatar-studio synth --identity $P --frames 40 --views 8 --seed 7 --scene ambient --out $S/round$P
    OMP_NUM_THREADS=1 avatar-studio train $S/front$P --model primitives --minutes 30 --out $S/scratch$P
    OMP_NUM_THREADS=1 avatar-studio personalize $S/front$P --minutes 3 --out $S/prior$P
    .venv/bin/python -m benchmarks.bench_beyond_views --round $S/round$P scratch=$S/scratch$P prior=$S/prior$P \\
        --whole $S/whole$P --out benchmarks/results/beyond_views_$P.json

`--whole FOLDER` puts the `scratch` and `prior` avatars together as a whole head (models/training/whole.py: what
`train` makes of a tracked video, its two parts trained 27 and 3 minutes) and scores it as `whole`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.capture.dataset import load_split
from models.capture.frames import frame_camera, load_mask, load_rgb
from models.head.lbs import rotation_matrix_from_axis_angle
from models.training.metrics import edge_density, psnr
from models.training.whole import compose
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

ANGLES_DEG = (0, 45, 90, 135, 180)


def angle_from_face_deg(frame) -> float:
    """Degrees between where the face looks (the head's +z turned by the frame's root pose) and the way from the
    head (its translation) to the camera."""
    c = frame.controls
    turn = rotation_matrix_from_axis_angle(torch.as_tensor(np.asarray(c.root, np.float64)[None]))[0].numpy()
    facing = turn @ np.array([0.0, 0.0, 1.0])
    to_camera = np.asarray(frame.camera_to_world, np.float64)[:3, 3] - np.asarray(c.translation, np.float64)
    cos = facing @ to_camera / max(np.linalg.norm(to_camera), 1e-12)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def score(avatar, round_split, raster) -> dict:
    """PSNR of every test frame of the round capture, and their means by the nearest of ANGLES_DEG; and the edges
    the render shows within its figure beside the truth's within its mask (`edge_density`: a patchwork of boxes
    shows more edges than the person has)."""
    rows = []
    for f in round_split.frames:
        truth = load_rgb(f.image_path, avatar.background_colour())
        with torch.inference_mode():
            out = render_image(avatar, frame_camera(round_split, f), f.controls, RenderOptions(buffers=()), raster)
        angle = angle_from_face_deg(f)
        rgb = np.asarray(out["rgb"])
        row = {"angle_deg": round(angle, 1), "bucket": int(min(ANGLES_DEG, key=lambda a: abs(a - angle))),
               "psnr": psnr(rgb, truth), "edges": edge_density(rgb, np.asarray(out["opacity"]).reshape(rgb.shape[:2]))}
        if "mask_path" in f.extra:
            row["truth_edges"] = edge_density(truth, load_mask(f.extra["mask_path"]))
        rows.append(row)

    def by_angle(key: str, digits: int) -> dict:
        return {str(a): round(float(np.mean([r[key] for r in rows if r["bucket"] == a])), digits)
                for a in ANGLES_DEG if any(r["bucket"] == a and key in r for r in rows)}

    return {"psnr_by_angle": by_angle("psnr", 2), "edges_by_angle": by_angle("edges", 1),
            "truth_edges_by_angle": by_angle("truth_edges", 1), "frames": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("avatars", nargs="+", help="NAME=AVATAR_FOLDER")
    ap.add_argument("--round", type=Path, required=True, help="the capture all round (its test split is scored)")
    ap.add_argument("--out", type=Path, required=True, help="results JSON")
    ap.add_argument("--whole", type=Path, help="put the scratch= and prior= avatars together here as a whole head, and "
                                               "score it as whole")
    args = ap.parse_args()
    named = dict(item.split("=", 1) for item in args.avatars)
    if args.whole is not None:
        if not {"scratch", "prior"} <= named.keys():
            raise SystemExit("--whole needs scratch=FOLDER and prior=FOLDER")
        compose(Path(named["scratch"]), Path(named["prior"]), args.whole)
        args.avatars.append(f"whole={args.whole}")
    raster = Rasterizer(GLContext.headless())
    round_split = load_split(args.round, "test")
    results = {"round": str(args.round), "angles_deg": list(ANGLES_DEG), "avatars": {}}
    for item in args.avatars:
        name, folder = item.split("=", 1)
        avatar, meta = load_avatar(folder)
        results["avatars"][name] = {"folder": folder, "steps": meta.get("step"), **score(avatar, round_split, raster)}
        print(name, results["avatars"][name]["psnr_by_angle"], "edges", results["avatars"][name]["edges_by_angle"],
              "(the truth's", results["avatars"][name]["truth_edges_by_angle"], ")", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
