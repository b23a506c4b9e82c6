"""What the universal prior buys (Cao et al. 2022, Fig. 14 and Section 4.2): on a held-out person's scan, the held-out
PSNR of the prior's avatar after 0, 1, 3 ... minutes of personalisation, beside a person-specific primitives
avatar trained from scratch on the same frames for the same minutes; one run at a time, nothing else running.

    .venv/bin/python -m benchmarks.bench_prior --prior resources/prior --scan out/scan1000 \
        [--minutes 0 1 3] [--scratch-minutes 1 3 10] [--out benchmarks/results/prior.json]

Two halves may run side by side on the two cores, one thread each (`--threads 1`; `--minutes` with no value runs
no prior rows, `--scratch-minutes` with none no from-scratch rows), the second joining the first's rows (`--join
FIRST.json`: it waits for that file) into one table and chart.

The scan: `avatar-studio synth --identity 1000 --frames 60 --size 128 --scene ambient --out out/scan1000` (seeds
from 1000 up are never in a corpus). Writes the JSON and a chart beside it (PNG)."""

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
CLI = [sys.executable, "-m", "app.cli"]


THREADS: int | None = None
"""Torch threads of every command run (OMP_NUM_THREADS; None: torch's default)."""


def run(args: list[str]) -> float:
    env = os.environ | ({"OMP_NUM_THREADS": str(THREADS)} if THREADS else {})
    t0 = time.perf_counter()
    subprocess.run(CLI + args, check=True, cwd=REPO, stdout=subprocess.DEVNULL, env=env)
    return time.perf_counter() - t0


def add_halves_options(p: argparse.ArgumentParser) -> None:
    """--threads and --join: a benchmark's prior and from-scratch halves run side by side, one thread each."""
    p.add_argument("--threads", type=int, help="torch threads of each command (default: torch's)")
    p.add_argument("--join", type=Path, help="a results JSON of this benchmark whose rows join this run's")


def start_results(a: argparse.Namespace, results: dict) -> dict:
    """This run's results, with the thread count set for every command."""
    global THREADS
    THREADS = a.threads
    results["threads"] = a.threads
    return results


POLL_S = 10.0
"""How often a half looks for the other half's file."""


def write_results(a: argparse.Namespace, results: dict, same: tuple[str, ...], order: tuple[str, ...]) -> dict:
    """Writes the results to --out, with the rows of --join's half where given, every key's rows in `order`: that
    half runs beside this one, so its file is waited for (it must share this run's `same` keys and thread
    count)."""
    if a.join is not None:
        if not a.join.is_file():
            print(f"waiting for {a.join} (the other half)", flush=True)
        while not a.join.is_file():
            time.sleep(POLL_S)
        joined = json.loads(a.join.read_text())
        if any(joined.get(k) != results[k] for k in (*same, "threads")):
            raise SystemExit(f"{a.join}: not a half of this run ({', '.join(f'{k} {joined.get(k)}' for k in same)}, "
                             f"{joined.get('threads')} threads)")
        for key in ("prior", "scratch"):
            results[key] = [*joined.get(key, []), *results.get(key, [])]
    for key in ("prior", "scratch"):
        results[key] = sorted(results.get(key, []), key=lambda r: tuple(r[k] for k in order))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = a.out.with_name(a.out.name + ".partial")
    tmp.write_text(json.dumps(results, indent=1))
    tmp.replace(a.out)  # whole or absent: the other half may be polling for it
    return results


def add_row(results: dict, key: str, row: dict) -> None:
    """A row of `key`'s rows, shown as it comes (write_results puts them in order)."""
    results[key].append(row)
    print(key, row, flush=True)


def evaluate(avatar: Path, scan: Path, round_views: Path | None) -> dict:
    """Held-out metrics on the scan's test frames, and where given on a capture of the same person from cameras
    all round the head (views the scan never had)."""
    row = {"steps": json.loads((avatar / "avatar.json").read_text()).get("step")}
    for key, data in (("", scan), ("round_", round_views)):
        if data is None:
            continue
        out = avatar / f"eval_{key.rstrip('_') or 'scan'}"
        run(["eval", str(avatar), str(data), "--split", "test", "--out", str(out)])
        m = json.loads((out / "metrics.json").read_text())
        row |= {f"{key}psnr": round(m["metrics"]["psnr"], 2), f"{key}ssim": round(m["metrics"]["ssim"], 4),
                f"{key}test_frames": m["frames"]}
        behind = views_behind(data) if key == "round_" else []
        if behind:  # (no frame from behind: no figure, not 0 dB)
            row |= {"behind_psnr": round(sum(m["per_frame"][k]["psnr"] for k in behind) / len(behind), 2),
                    "behind_test_frames": len(behind)}
    return row


def views_behind(data: Path, split: str = "test") -> list[int]:
    """The frames of a capture's split whose camera sees the back of the head: more than 90 degrees from where the
    face looks (the head's +z turned by the frame's root pose), seen from the head's place (its translation).

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> cams = [[0, 0, 1.2], [1.2, 0, 0], [0, 0, -1.2]]
    >>> frames = [{"transform_matrix": [[1, 0, 0, x], [0, 1, 0, y], [0, 0, 1, z], [0, 0, 0, 1]], "controls": {"pose":
    ...     {"root": [0.0, 0.7, 0.0]}, "translation": [0.0, 0.0, 0.0]}} for x, y, z in cams]  # the face turned 40 deg
    >>> _ = (d / "transforms_test.json").write_text(json.dumps({"frames": frames}))
    >>> views_behind(d)  # the side camera is 50 degrees from the face, the back one 140
    [2]
    """
    import numpy as np
    import torch

    from models.head.lbs import rotation_matrix_from_axis_angle

    frames = json.loads((data / f"transforms_{split}.json").read_text())["frames"]
    behind = []
    for k, f in enumerate(frames):
        controls = f["controls"]
        turn = rotation_matrix_from_axis_angle(torch.tensor([controls["pose"]["root"]], dtype=torch.float64))[0]
        facing = turn.numpy() @ np.array([0.0, 0.0, 1.0])
        to_camera = np.asarray(f["transform_matrix"], dtype=float)[:3, 3] - np.asarray(controls.get(
            "translation", [0.0, 0.0, 0.0]), dtype=float)
        if facing @ to_camera < 0:
            behind.append(k)
    return behind


def chart(results: dict, path: Path, x: str = "minutes", xlabel: str | None = None, title: str | None = None
          ) -> None:
    """The prior's and the from-scratch avatars' held-out PSNR against `x` (minutes, or a scan's frames: a log axis
    at the values measured), and where measured from cameras all round the head."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for key, label, colour in (("prior", "prior, personalised", "tab:green"), ("scratch", "primitives from scratch",
                                                                                  "tab:red")):
        rows = results[key]
        ax.plot([r[x] for r in rows], [r["psnr"] for r in rows], "o-", color=colour, label=label)
        if rows and "round_psnr" in rows[0]:
            ax.plot([r[x] for r in rows], [r["round_psnr"] for r in rows], "s--", color=colour,
                    label=label + ": cameras all round")
        if rows and "behind_psnr" in rows[0]:
            ax.plot([r[x] for r in rows], [r["behind_psnr"] for r in rows], "^:", color=colour,
                    label=label + ": cameras behind the head")
    if x == "frames":
        ax.set_xscale("log")
        ax.set_xticks(results["frames"], [str(f) for f in results["frames"]])
    threads = results.get("threads")
    ax.set_xlabel(xlabel or "minutes of training on the scan "
                  + (f"({threads} thread{'s' if threads > 1 else ''} a run)" if threads else "(2 CPU cores)"))
    ax.set_ylabel("held-out PSNR (dB)")
    ax.set_title(title or f"A held-out person ({results['scan_frames']} scan frames): what the prior buys",
                 fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--prior", type=Path, default=REPO / "resources" / "prior")
    p.add_argument("--scan", type=Path, required=True)
    p.add_argument("--minutes", type=float, nargs="*", default=[0.0, 1.0, 3.0])
    p.add_argument("--scratch-minutes", type=float, nargs="*", default=[1.0, 3.0, 10.0])
    add_halves_options(p)
    p.add_argument("--round-views", type=Path, help="a capture of the same person from cameras all round the head "
                   "(synth --views 4): each avatar is measured on its test frames too")
    p.add_argument("--keep", type=Path, help="keep the avatars in this folder (default: a temporary one)")
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "prior.json")
    a = p.parse_args()
    train = json.loads((a.scan / "transforms_train.json").read_text())
    results = start_results(a, {"prior": [], "scratch": [], "scan": str(a.scan), "scan_frames": len(train["frames"])})
    with tempfile.TemporaryDirectory() as scratch_dir:
        tmp = a.keep or Path(scratch_dir)
        for m in a.minutes:
            out = Path(tmp) / f"prior_{m:g}"
            seconds = run(["personalize", str(a.scan), "--prior", str(a.prior), "--out", str(out), "--minutes",
                           str(m)])
            add_row(results, "prior", {"minutes": m, "seconds": round(seconds, 1),
                                       **evaluate(out, a.scan, a.round_views)})
        for m in a.scratch_minutes:
            out = Path(tmp) / f"scratch_{m:g}"
            seconds = run(["train", str(a.scan), "--model", "primitives", "--effects", "none", "--minutes", str(m),
                           "--out", str(out)])
            add_row(results, "scratch", {"minutes": m, "seconds": round(seconds, 1),
                                         **evaluate(out, a.scan, a.round_views)})
    results = write_results(a, results, ("scan", "scan_frames"), ("minutes",))
    chart(results, a.out.with_suffix(".png"))
    print(f"wrote {a.out} and {a.out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
