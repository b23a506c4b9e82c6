"""Real people held out by view: each clip tracked with `track --split view` (the tenth of the frames turned furthest
from the usual facing held out), an avatar trained on the rest in each way asked for, and each measured on the
held-out turns (`eval --split test`) and on its validation frames (between the training frames). The ways:
`scratch` is `train --from-scratch` (volumetric primitives from nothing), `default` is `train` as a user runs it
(on a tracked video: a whole head, the primitives from scratch and the universal prior personalised beyond the
video's views), `prior` is `train --model prior --prior PRIOR`.
Two runs at a time, one thread each (the machine's two cores).

    .venv/bin/python -m benchmarks.bench_held_out_views --minutes 30 --ways scratch default \\
        --clips more/child_looking_around more/grimaces_green_screen expressions_d3 \\
        --work out/held_out_views --out benchmarks/results/held_out_views.json

Clips are named as under ../shared/data/video/ (without .mp4). A run whose avatar exists is measured, not trained
again (`--work` keeps them); rows of an earlier JSON at --out are kept unless the same clip and way ran again."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
VIDEOS = REPO.parent / "shared" / "data" / "video"
CLI = [sys.executable, "-m", "app.cli"]
WAYS = {"scratch": ["--from-scratch"], "default": [], "prior": ["--model", "prior"]}


def run(args: list[str], log: Path) -> None:
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    with open(log, "w") as f:
        subprocess.run(CLI + args, check=True, cwd=REPO, stdout=f, stderr=subprocess.STDOUT, env=env)


def capture_of(clip: str, work: Path, split: str = "view") -> Path:
    """The clip tracked into work/NAME (split by view, or by time), once."""
    capture = work / Path(clip).name
    if not (capture / "transforms_test.json").is_file():
        run(["track", str(VIDEOS / f"{clip}.mp4"), "--split", split, "--no-overlay", "--out", str(capture)],
            work / f"track_{Path(clip).name}.log")
    return capture


def train_and_measure(clip: str, way: str, capture: Path, work: Path, minutes: float, prior: Path | None) -> dict:
    avatar = work / f"{capture.name}_{way}"
    extra = WAYS[way] + (["--prior", str(prior)] if prior is not None and way != "scratch" else [])
    if not (avatar / "avatar.json").is_file():
        run(["train", str(capture), "--minutes", str(minutes), "--out", str(avatar), *extra],
            work / f"train_{avatar.name}.log")
    row = {"clip": clip, "way": way}
    meta = json.loads((avatar / "avatar.json").read_text())
    row.update(model=meta["model"], steps=meta["provenance"]["steps"],
               minutes=round(meta["provenance"].get("seconds", 0) / 60, 1))
    for split in ("test", "val"):
        out = work / f"{avatar.name}_eval_{split}"
        if not (out / "metrics.json").is_file():
            run(["eval", str(avatar), str(capture), "--split", split, "--out", str(out)], work / f"eval_{out.name}.log")
        m = json.loads((out / "metrics.json").read_text())["metrics"]
        keys = ("psnr", "psnr_person", "ssim", "face_mse", "offset_px", "render_ms")
        row[split] = {k: round(float(m[k]), 4) for k in keys if k in m}
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", nargs="+", default=["more/child_looking_around", "more/grimaces_green_screen",
                                                   "expressions_d3"])
    ap.add_argument("--ways", nargs="+", choices=list(WAYS), default=["scratch", "default"])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--prior", type=Path, default=None, help="the prior of `default` and `prior` (default: shipped)")
    ap.add_argument("--work", type=Path, default=Path("out/held_out_views"))
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/held_out_views.json"))
    ap.add_argument("--parallel", type=int, default=2)
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    captures = {c: capture_of(c, args.work) for c in args.clips}
    jobs = [(c, w) for c in args.clips for w in args.ways]
    with ThreadPoolExecutor(args.parallel) as pool:
        rows = list(pool.map(lambda job: train_and_measure(job[0], job[1], captures[job[0]], args.work,
                                                           args.minutes, args.prior), jobs))
    kept = json.loads(args.out.read_text())["rows"] if args.out.is_file() else []
    done = {(r["clip"], r["way"]) for r in rows}
    rows = [r for r in kept if (r["clip"], r["way"]) not in done] + rows
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"prior": str(args.prior or "shipped"), "rows": rows}, indent=1) + "\n")
    for r in rows:
        print(f"{r['clip']:32s} {r['way']:8s} {r['model']:10s} {r['steps']:6d} steps  held out "
              f"{r['test']['psnr']:.2f} dB (SSIM {r['test']['ssim']:.3f})  validation {r['val']['psnr']:.2f} dB")
    print(f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
