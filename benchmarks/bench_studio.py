"""The studio's measured figures on this machine, for each window size and avatar: interface frames per second
idle, while the neural render runs, and (first avatar) while a training job runs; the latency from a slider
move to each pass's pixels (draft, preview, final: median and worst of --moves moves, each made after the last
one's final pass, while the Quality panel times the presets); seconds for a 120-frame 256x256 turntable at each
preset.

    .venv/bin/python -m benchmarks.bench_studio [--avatar resources/demo_avatar --avatar OTHER]
        [--dataset out/demo_capture] [--sizes 1280x800,1920x1080] [--out benchmarks/results/studio.json]

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

import numpy as np

from models.avatars.quality import PRESET_NAMES

REPO = Path(__file__).resolve().parents[1]


def studio_run(display: str, avatar: Path, steps: list[dict], work: Path, size: tuple[int, int]) -> dict:
    script, report = work / "script.json", work / "report.json"
    script.write_text(json.dumps({"report": str(report), "steps": steps}))
    subprocess.run([sys.executable, "-m", "app.cli", "studio", str(avatar), "--script", str(script),
                    "--width", str(size[0]), "--height", str(size[1])], cwd=REPO,
                   env={**os.environ, "DISPLAY": display}, check=True, timeout=1800)
    return json.loads(report.read_text())


def latency_steps(moves: int) -> list[dict]:
    """`moves` slider moves, each after the last one's final pass is on screen and a few idle frames (the Quality
    panel's timing of the presets starts when the controls rest: a move must not wait behind it)."""
    steps: list[dict] = [{"refine_to": "final"}, {"wait_render": "final"}]
    for k in range(moves):
        steps += [{"wait_frames": 5}, {"expression": k % 4, "value": 0.1 + 0.08 * k}, {"wait_render": "final"},
                  {"record_latency": True}]
    return steps


def summary(latencies: list[dict], name: str) -> dict:
    ms = [r[name] for r in latencies if name in r]
    return {"median": round(float(np.median(ms)), 1), "worst": round(float(np.max(ms)), 1), "moves": len(ms)} \
        if ms else {}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--avatar", type=Path, action="append",
                   help="avatar folders (repeat: each measured in the same run); default the shipped demo")
    p.add_argument("--dataset", type=Path, default=REPO / "out" / "demo_capture",
                   help="the capture the training job trains on")
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "studio.json")
    p.add_argument("--sizes", default="1280x800,1920x1080", help="window sizes, WxH comma-separated")
    p.add_argument("--moves", type=int, default=10)
    p.add_argument("--turntable-frames", type=int, default=120, help="0: no turntables")
    p.add_argument("--latency-only", action="store_true",
                   help="only the slider-move latencies (no frame rates, no training job: no dataset needed)")
    a = p.parse_args()
    avatars = a.avatar or [REPO / "resources" / "demo_avatar"]
    sizes = [tuple(int(v) for v in s.split("x")) for s in a.sizes.split(",")]
    display = ":89"
    big = max(w for w, _ in sizes), max(h for _, h in sizes)
    xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", f"{big[0] + 64}x{big[1] + 64}x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1)
    results: dict = {"machine": f"{os.cpu_count()} CPU cores, no GPU (Mesa llvmpipe)", "moves": a.moves,
                     "windows": {}}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            orbit = [step for k in range(12) for step in ({"orbit": 15}, {"wait_frames": 10})]
            for size in sizes:
                window: dict = {}
                for avatar in avatars:
                    r = studio_run(display, avatar, latency_steps(a.moves), work, size)
                    row = {"latency_ms": {name: summary(r["latencies"], name) for name in ("first", *PRESET_NAMES)},
                           "render_ms": {name: summary(r["latencies"], f"{name} render") for name in PRESET_NAMES},
                           "presets_measured_in_window": r["presets"]}
                    key = str(avatar.relative_to(REPO) if avatar.is_relative_to(REPO) else avatar)
                    if a.latency_only:
                        window[key] = row
                        print(f"{size[0]}x{size[1]} {avatar.name}: {json.dumps(row)}", flush=True)
                        continue
                    steps = [{"refine_to": "final"}, {"wait_render": "final"}, {"wait_frames": 180}, *orbit,
                             {"wait_render": "final"}]
                    r = studio_run(display, avatar, steps, work, size)
                    row["fps_idle"], row["fps_rendering"] = r["fps_idle"], r["fps_rendering"]
                    window[key] = row
                    print(f"{size[0]}x{size[1]} {avatar.name}: {json.dumps(row)}", flush=True)
                if a.latency_only:
                    results["windows"][f"{size[0]}x{size[1]}"] = window
                    continue
                r = studio_run(display, avatars[0], [
                    {"train": {"dataset": str(a.dataset), "out": str(work / f"job_{size[0]}x{size[1]}"), "minutes": 10,
                               "effects": "all"}},  # a folder a window: the first job leaves its avatar
                    {"wait_frames": 600}, *orbit, {"cancel_jobs": True}, {"wait_job": True}], work, size)
                window["fps_training"] = r["fps_training"]
                r = studio_run(display, avatars[0], [
                    {"wait_render": "draft"}, {"seek": 1.0}, {"expression": 0, "value": 0.8}, {"jaw_open_deg": 20},
                    {"view": {"yaw_deg": -20.0}}, {"key": True}, {"play": True}, {"wait_frames": 240},
                    {"play": False}], work, size)
                window["fps_playing"] = r["fps_playing"]
                results["windows"][f"{size[0]}x{size[1]}"] = window
        for preset in ("draft", "preview", "final") if a.turntable_frames else ():
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-m", "app.cli", "turntable", str(avatars[0]), "--out",
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
