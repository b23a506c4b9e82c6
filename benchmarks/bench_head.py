"""Skinning speed (posed meshes per second) and GL preview frame rate, on this machine.

    .venv/bin/python -m benchmarks.bench_head [--ict PATH] [--out benchmarks/results/head.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import torch

from models.head.controls import Controls
from models.head.head import Head
from models.head.ict import load_ict_npz
from models.head.model import HeadModel
from models.head.sources import load_builtin
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.preview import MeshFrame, PreviewRenderer, PreviewSettings

DEFAULT_ICT = Path(__file__).resolve().parents[2] / "shared" / "data" / "ict_facekit" / "ict_head.npz"


def time_it(fn, min_seconds: float = 2.0, warmup: int = 2) -> float:
    """Median seconds per call over repeated calls for at least `min_seconds`."""
    for _ in range(warmup):
        fn()
    times = []
    start = time.perf_counter()
    while time.perf_counter() - start < min_seconds or len(times) < 5:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def skinning_rate(model: HeadModel, batch: int) -> float:
    head = Head(model)
    rng = np.random.default_rng(0)
    args = {"shape": torch.as_tensor(rng.normal(0, 1, (batch, model.num_shape)), dtype=torch.float32),
            "expression": torch.as_tensor(rng.uniform(0, 1, (batch, model.num_expression)), dtype=torch.float32),
            "full_pose": torch.as_tensor(rng.normal(0, 0.2, (batch, model.num_joints, 3)), dtype=torch.float32),
            "translation": torch.zeros(batch, 3)}

    def run():
        with torch.inference_mode():
            head(**args)

    return batch / time_it(run)


def gl_fps(gl: GLContext, model: HeadModel, size: tuple[int, int], settings: PreviewSettings) -> float:
    renderer = PreviewRenderer(gl)
    verts = Head(model).pose(Controls())[0][0].detach().numpy()
    cam = framing_camera(model.template, 20, 5, width_px=size[0], height_px=size[1])
    frame = MeshFrame(verts, model.triangles)
    fps = 1.0 / time_it(lambda: renderer.render(frame, cam, settings))
    renderer.release()
    return fps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ict", type=Path, default=DEFAULT_ICT)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/head.json"))
    args = parser.parse_args()
    models = {"builtin": load_builtin()}
    if args.ict.is_file():
        models["ict"] = load_ict_npz(args.ict)
    results: dict = {"machine": f"{platform.processor() or platform.machine()}, {torch.get_num_threads()} threads",
                     "skinning_meshes_per_s": {}, "gl_fps": {}}
    for name, m in models.items():
        for batch in (1, 64):
            rate = skinning_rate(m, batch)
            results["skinning_meshes_per_s"][f"{name} ({m.num_vertices} v) batch {batch}"] = round(rate, 1)
            print(f"skinning {name:8s} batch {batch:3d}: {rate:8.1f} meshes/s")
    gl = GLContext.headless()
    cases = {
        "shadows+wireframe, 4x MSAA": PreviewSettings(pass_name="wireframe", shadows=True, samples=4),
        "shadows+wireframe, no MSAA": PreviewSettings(pass_name="wireframe", shadows=True, samples=1),
        "shaded only, no MSAA": PreviewSettings(shadows=False, samples=1),
    }
    for name, m in models.items():
        for label, settings in cases.items():
            fps = gl_fps(gl, m, (1024, 768), settings)
            results["gl_fps"][f"{name} 1024x768 {label}"] = round(fps, 1)
            print(f"GL {name:8s} 1024x768 {label}: {fps:6.1f} fps (with read-back)")
    results["gl_renderer"] = gl.renderer
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
