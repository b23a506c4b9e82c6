"""The studio's measured figures on this machine: interface frames per second idle, while the neural render
runs, and while a training job runs; slider-to-first-pixels latency; seconds for a 120-frame 256x256
turntable at each preset.

    .venv/bin/python -m benchmarks.bench_studio [--avatar resources/demo_avatar] [--dataset out/demo_capture]
        [--out benchmarks/results/studio.json]

Needs Xvfb (the window is real). Each figure comes from the studio's own clock (app/studio/app.py), read from
a scripted run's report.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def studio_run(display: str, avatar: Path, steps: list[dict], work: Path) -> dict:
    script, report = work / "script.json", work / "report.json"
    script.write_text(json.dumps({"report": str(report), "steps": steps}))
    subprocess.run([sys.executable, "-m", "app.cli", "studio", str(avatar), "--script", str(script)], cwd=REPO,
                   env={**os.environ, "DISPLAY": display}, check=True, timeout=1800)
    return json.loads(report.read_text())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--avatar", type=Path, default=REPO / "resources" / "demo_avatar")
    p.add_argument("--dataset", type=Path, default=REPO / "out" / "demo_capture")
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "studio.json")
    p.add_argument("--turntable-frames", type=int, default=120)
    a = p.parse_args()
    display = ":89"
    xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1)
    results: dict = {"machine": f"{os.cpu_count()} CPU cores, no GPU (Mesa llvmpipe)"}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            moves = [step for k in range(12) for step in ({"orbit": 15}, {"wait_frames": 10})]
            lat = []
            for k in range(5):  # latency: a slider move to the first pixels of its draft pass
                r = studio_run(display, a.avatar, [{"wait_render": "final"}, {"expression": 0, "value": 0.2 * k + 0.2},
                                                   {"wait_render": "draft"}], work)
                lat.append(r["latency_ms"])
            results["latency_ms"] = lat
            r = studio_run(display, a.avatar, [{"refine_to": "final"}, {"wait_render": "final"}, {"wait_frames": 180},
                                               *moves, {"wait_render": "final"}], work)
            results["fps_idle"], results["fps_rendering"] = r["fps_idle"], r["fps_rendering"]
            results["presets_measured_in_window"] = r["presets"]
            r = studio_run(display, a.avatar, [
                {"train": {"dataset": str(a.dataset), "out": str(work / "job"), "minutes": 10, "effects": "all"}},
                {"wait_frames": 600}, *moves, {"cancel_jobs": True}, {"wait_job": True}], work)
            results["fps_training"] = r["fps_training"]
        for preset in ("draft", "preview", "final"):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-m", "app.cli", "turntable", str(a.avatar), "--out",
                                str(Path(tmp) / "t.mp4"), "--frames", str(a.turntable_frames), "--size", "256",
                                "--preset", preset], cwd=REPO, check=True)
                results[f"turntable_{a.turntable_frames}x256_{preset}_s"] = round(time.perf_counter() - t0, 1)
    finally:
        xvfb.terminate()
    print(json.dumps(results, indent=1))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
