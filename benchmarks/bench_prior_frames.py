"""How few frames a scan may have (Cao et al. 2022, Fig. 14): a held-out person's scan cut to its first 1, 3, 9, 33
training frames (the same test frames for all), the prior personalised on each and a primitives avatar trained
from scratch on each, the same minutes; held-out PSNR against the frames the scan had. One run at a time, nothing
else running.

    .venv/bin/python -m benchmarks.bench_prior_frames --prior resources/prior --scan out/scan1000 \
        [--frames 1 3 9 33] [--minutes 3] [--out benchmarks/results/prior_frames.json]

The scan as for benchmarks/bench_prior.py (`synth --identity 1000 --frames 60 --size 128 --scene ambient`). Writes
the JSON and a chart beside it (PNG). As bench_prior, the halves may run side by side at one thread each
(`--kinds prior` beside `--kinds scratch`, `--threads 1`, the second with `--join FIRST.json`: it waits for
that file and writes the joined table)."""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.bench_prior import REPO, add_halves_options, add_row, chart, evaluate, run, start_results, write_results


def scan_with(scan: Path, frames: int, out: Path) -> Path:
    """The scan with only `frames` of its training frames (spread evenly over them, the first among them), copied
    (a capture's files must lie inside its folder: links out of it are refused)."""
    shutil.copytree(scan, out)
    train = json.loads((scan / "transforms_train.json").read_text())
    keep = np.unique(np.linspace(0, len(train["frames"]) - 1, frames).round().astype(int))
    train["frames"] = [train["frames"][k] for k in keep]
    (out / "transforms_train.json").write_text(json.dumps(train))
    return out


def frames_chart(results: dict, path: Path) -> None:
    threads = results.get("threads")
    cores = f"{threads} thread{'s' if threads > 1 else ''} a run" if threads else "2 CPU cores"
    chart(results, path, "frames", f"training frames in the scan ({results['minutes']:g} minutes of training each, "
          f"{cores})", "A held-out person from few frames: what the prior buys")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--prior", type=Path, default=REPO / "resources" / "prior")
    p.add_argument("--scan", type=Path, required=True)
    p.add_argument("--frames", type=int, nargs="+", default=[1, 3, 9, 33])
    p.add_argument("--minutes", type=float, default=3.0)
    p.add_argument("--kinds", nargs="+", choices=("prior", "scratch"), default=["prior", "scratch"])
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "prior_frames.json")
    add_halves_options(p)
    a = p.parse_args()
    results = start_results(a, {"scan": str(a.scan), "frames": a.frames, "minutes": a.minutes, "prior": [],
                                "scratch": []})
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.frames:
            scan = scan_with(a.scan, n, Path(tmp) / f"scan_{n}")
            for key, args in (("prior", ["personalize", str(scan), "--prior", str(a.prior)]),
                              ("scratch", ["train", str(scan), "--model", "primitives", "--effects", "none"])):
                if key not in a.kinds:
                    continue
                out = Path(tmp) / f"{key}_{n}"
                seconds = run([*args, "--out", str(out), "--minutes", str(a.minutes)])
                add_row(results, key, {"frames": n, "seconds": round(seconds, 1),
                                                 **evaluate(out, a.scan, None)})
    results = write_results(a, results, ("scan", "frames", "minutes"), ("frames",))
    frames_chart(results, a.out.with_suffix(".png"))
    print(f"wrote {a.out} and {a.out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
