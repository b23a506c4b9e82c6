"""Seconds to synthesize a capture (300 frames at 256x256 by default) for each scene, headless.

    .venv/bin/python -m benchmarks.bench_synth [--head HEAD] [--frames 300] [--size 256]
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

from models.capture.synthetic import SynthConfig, synthesize
from models.head.sources import load_head
from render.gl.context import GLContext


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--head", default="builtin")
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/synth.json"))
    a = p.parse_args()
    head = load_head(a.head)
    gl = GLContext.headless()
    results = json.loads(a.out.read_text()) if a.out.is_file() else {}
    for scene in ("ambient", "studio", "sun"):
        tmp = Path(tempfile.mkdtemp())
        try:
            s = synthesize(SynthConfig(head=a.head, scene=scene, frames=a.frames, size=a.size, out=tmp / "c"),
                           head, gl)
        finally:
            shutil.rmtree(tmp)
        key = f"{head.name} {scene} {a.frames} frames {a.size}x{a.size}"
        results[key] = round(s["seconds"], 1)
        print(f"{key}: {s['seconds']:.1f} s ({a.frames / s['seconds']:.1f} frames/s)")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
