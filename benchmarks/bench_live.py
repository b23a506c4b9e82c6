"""Live driving measured in the real studio window under Xvfb: a video file played in real time (as a camera would
deliver it) drives each avatar; for every live render shown, the time from its source frame's arrival to the
avatar's pixels on screen (median, 90th percentile, worst), and how many such renders a second the window shows;
the tracker's time per frame, frames dropped, and the pass each render was. Beside them, in the same window, the
studio's own slider-to-final-pixels latency (benchmarks/bench_studio.py's, 5 moves): on a machine others share,
it shows how far the load has slowed everything (about 70 ms on this one idle).

    .venv/bin/python -m benchmarks.bench_live [--avatar resources/demo_avatar --avatar out/real/d3_view_win]
        [--video ../shared/data/video/expressions_d3.mp4] [--size 1440x900] [--runs 1]
        [--live-pass auto --live-pass final] [--guide held --guide follows]
        [--out benchmarks/results/live.json]

The first second of each run is left out (the tracker's process starts and its first frames queue behind the
renderer's first pose). Each figure comes from the studio's own clock (app/studio/app.py, LiveFigures), read from a
scripted run's report; the figures are only as good as the machine is idle.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.bench_studio import latency_steps, studio_run, summary

REPO = Path(__file__).resolve().parents[1]
WARM_S = 1.0
"""Renders shown within this long of the first are left out."""


def live_row(report: dict) -> dict:
    """The figures of one run's report."""
    live = report["live"]
    shown = list(zip(live["shown_at_s"], live["latency_ms"], strict=True))
    kept = [ms for t, ms in shown if t >= shown[0][0] + WARM_S] if shown else []
    times = [t for t, _ in shown if t >= shown[0][0] + WARM_S] if shown else []
    return {"render_px": live["render_px"], "passes": live["passes"], "shown": len(kept),
            "fps_shown": round((len(times) - 1) / (times[-1] - times[0]), 2) if len(times) > 1 else 0.0,
            "latency_ms": {"median": round(float(np.median(kept)), 1), "p90": round(float(np.percentile(kept, 90)), 1),
                           "worst": round(float(np.max(kept)), 1)} if kept else {},
            "track_ms_median": live["track_ms_median"], "age_at_request_ms_median": live["age_at_request_ms_median"],
            "render_ms_median": live["render_ms_median"], "delivery_ms_median": live["delivery_ms_median"],
            "poses": live["poses"], "dropped": live["dropped"],
            "fps_window": report["fps_rendering"]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--avatar", type=Path, action="append", help="avatar folders (repeat); default the shipped demo")
    p.add_argument("--video", type=Path, default=REPO.parent / "shared" / "data" / "video" / "expressions_d3.mp4")
    p.add_argument("--size", default="1440x900", help="the window, WxH (1440x900 shows the render at 256 px or more)")
    p.add_argument("--runs", type=int, default=1, help="runs of the whole video for each avatar")
    p.add_argument("--live-pass", action="append", choices=("auto", "draft", "preview", "final"),
                   help="the pass live poses render (repeat: each measured); default auto, the finest that keeps up")
    p.add_argument("--guide", action="append", choices=("held", "follows"),
                   help="the guide while live (repeat: each measured): held (the studio's default) or drawn anew "
                        "for every live pose; default held")
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "live.json")
    a = p.parse_args()
    if not a.video.is_file():
        raise SystemExit(f"{a.video}: no such video (--video)")
    avatars = a.avatar or [REPO / "resources" / "demo_avatar"]
    size = tuple(int(v) for v in a.size.split("x"))
    display = ":90"
    xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", f"{size[0] + 64}x{size[1] + 64}x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1)
    load = os.getloadavg()[0]
    results: dict = {"machine": f"{os.cpu_count()} CPU cores, no GPU (Mesa llvmpipe)", "video": str(a.video),
                     "window": a.size, "load_average_1min_at_start": round(load, 2), "avatars": {}}
    steps = lambda live_pass, guide: [{"refine_to": "final"}, {"wait_render": "final"}, {"wait_frames": 60},
                                      {"live_pass": live_pass}, {"live_guide": guide == "follows"},
                                      {"live": str(a.video)}, {"wait_live_end": True, "timeout_s": 120}]
    try:
        for avatar in avatars:
            avatar = avatar.resolve()
            key = str(avatar.relative_to(REPO) if avatar.is_relative_to(REPO) else avatar)
            runs = []
            for live_pass, guide in itertools.product(a.live_pass or ["auto"], a.guide or ["held"]):
                for _ in range(a.runs):
                    with tempfile.TemporaryDirectory() as tmp:
                        row = live_row(studio_run(display, avatar, steps(live_pass, guide), Path(tmp), size))
                    runs.append({"live_pass": live_pass, "guide": guide, **row})
                    print(f"{key}: {json.dumps(runs[-1])}", flush=True)
            with tempfile.TemporaryDirectory() as tmp:
                slider = summary(studio_run(display, avatar, latency_steps(5), Path(tmp), size)["latencies"], "final")
            print(f"{key}: slider to final pixels {json.dumps(slider)}", flush=True)
            results["avatars"][key] = {"live": runs, "slider_to_final_pixels_ms": slider}
    finally:
        xvfb.terminate()
    results["load_average_1min_at_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(results, indent=1))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
