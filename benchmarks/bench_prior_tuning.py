"""Which parts of the prior to fine-tune, and at which learning rate (Cao et al. 2022, Table 2 and Section 4.2.5: the
seed fine-tunes at 1e-3): on a held-out person's scan, `personalize` for the same minutes with every weight or
the decoder alone (the encoders kept), at several learning rates; held-out PSNR on the scan's test frames and
from cameras all round the head.

    .venv/bin/python -m benchmarks.bench_prior_tuning --prior resources/prior --scan out/scan1000 \\
        --round-views out/round1000 [--tune all decoder] [--lr 3e-4 1e-3 3e-3] [--minutes 3] \\
        [--out benchmarks/results/prior_tuning.json]

The scan and the round views as for benchmarks/bench_prior.py. `--threads 1` with `--tune all` beside `--tune
decoder --join FIRST.json` runs the two halves side by side (the second waits for the first's file and writes
the joined table)."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from benchmarks.bench_prior import REPO, add_halves_options, add_row, evaluate, run, start_results, write_results


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--prior", type=Path, default=REPO / "resources" / "prior")
    p.add_argument("--scan", type=Path, required=True)
    p.add_argument("--round-views", type=Path)
    p.add_argument("--tune", nargs="+", choices=("all", "decoder"), default=["all", "decoder"])
    p.add_argument("--lr", type=float, nargs="+", default=[3e-4, 1e-3, 3e-3])
    p.add_argument("--minutes", type=float, default=3.0)
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "prior_tuning.json")
    add_halves_options(p)
    a = p.parse_args()
    results = start_results(a, {"scan": str(a.scan), "prior_folder": str(a.prior), "minutes": a.minutes,
                                "prior": [], "scratch": []})
    with tempfile.TemporaryDirectory() as tmp:
        for tune in a.tune:
            for lr in a.lr:
                out = Path(tmp) / f"{tune}_{lr:g}"
                seconds = run(["personalize", str(a.scan), "--prior", str(a.prior), "--out", str(out), "--minutes",
                               str(a.minutes), "--lr", str(lr), "--tune", tune])
                add_row(results, "prior", {"tune": tune, "lr": lr, "seconds": round(seconds, 1),
                                           **evaluate(out, a.scan, a.round_views)})
    write_results(a, results, ("scan", "prior_folder", "minutes"), ("tune", "lr"))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
