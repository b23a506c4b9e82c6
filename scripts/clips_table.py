"""The README's table of how the defaults do on every shared clip, from the two runs of `benchmarks.bench_clips`
kept in benchmarks/results: a row a clip of the 6-minute run, with the 30-minute run's steps, held-out and
validation PSNR beside it where that clip was run for 30 minutes. SSIM, FaceMSE (the face's pixels) and ms a
capture frame are the longest run's of that clip. A 30-minute run on another processor than the 6-minute run's (a
row's `machine`; rows without one ran on the Intel Xeon of the first runs) has its steps marked with an asterisk.

    .venv/bin/python scripts/clips_table.py [SIX.json [THIRTY.json]]   # prints the markdown table

`--minutes` prints instead docs/results.md's table of the clips run for 3, 10 and 30 minutes on one processor
(benchmarks/results/clips_{3,10,30}min.json): held-out PSNR and steps at each, and 10 minutes against 30.

    .venv/bin/python scripts/clips_table.py --minutes"""

from __future__ import annotations

import json
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
XEON = "Intel(R) Xeon(R) Processor, 2 cores"
"""The processor of the runs whose rows name none (before rows named it)."""
HEADER = ("| clip | frames (train/val/test) | face, video / dataset (px) | landmark error (px) | steps, 6 / 30 min "
          "| held out, 6 min | validation, 6 min | held out, 30 min | validation, 30 min "
          "| SSIM | FaceMSE | ms a frame |")


def rows_by_clip(path: Path) -> dict[str, dict]:
    """A results file's rows by clip name; none where the file is not there."""
    if not path.is_file():
        return {}
    return {row["clip"]: row for row in json.loads(path.read_text())["rows"]}


def other_processor(row: dict, other: dict | None) -> str:
    """"*" where the run `other` of the same clip (the 30-minute one beside a 6-minute `row`; any length beside the
    10-minute row in the minutes table) ran on another processor than `row`'s, else "".

    >>> other_processor({}, {"machine": "AMD EPYC, 2 cores"}), other_processor({}, {}), other_processor({}, None)
    ('*', '', '')
    """
    return "*" if other and other.get("machine", XEON) != row.get("machine", XEON) else ""


def table(six: dict[str, dict], thirty: dict[str, dict]) -> list[str]:
    """The table's lines: header, rule, a row a clip of the 6-minute run, in its order."""
    lines = [HEADER, "|" + "---|" * HEADER.count(" | ") + "---|"]
    for clip, row in six.items():
        long = thirty.get(clip)
        frames, last = row["frames"], (long or row)["test"]
        cells = [f"`{clip}`", f"{frames['train']}/{frames['val']}/{frames['test']}",
                 f"{row['source_face_px']:.0f} / {row['face_px']:.0f}", f"{row['landmark_error_px']['median']:.2f}",
                 f"{row['steps']} / {long['steps'] if long else '-'}{other_processor(row, long)}",
                 f"{row['test']['psnr']:.2f}", f"{row['val']['psnr']:.2f}",
                 f"**{long['test']['psnr']:.2f}**" if long else "-", f"{long['val']['psnr']:.2f}" if long else "-",
                 f"{last['ssim']:.3f}", f"{last['face_mse']:.4f}", f"{last['render_ms']:.0f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def minutes_table(runs: dict[int, dict[str, dict]]) -> list[str]:
    """The lines of a table of the clips of the 10-minute run: held-out PSNR (steps) after each run's minutes
    (runs: minutes -> rows by clip; "-" where a clip has no such run; "*" where a run's processor is not the
    10-minute run's), and the 10-minute figure less the 30-minute one.

    >>> row = lambda psnr, steps, **more: {"test": {"psnr": psnr}, "steps": steps, **more}
    >>> lines = minutes_table({3: {}, 10: {"a": row(29.18, 2023)}, 30: {"a": row(29.24, 3914, machine="x")}})
    >>> lines[0]
    '| clip | 3 minutes | 10 minutes | 30 minutes | 10 against 30 |'
    >>> lines[2]
    '| `a` | - | 29.18 (2023) | 29.24 (3914)* | -0.06 |'
    """
    minutes = sorted(runs)
    header = "| clip | " + " | ".join(f"{m} minutes" for m in minutes) + " | 10 against 30 |"
    lines = [header, "|" + "---|" * (len(minutes) + 2)]
    for clip, ten in runs[10].items():
        cells = [f"`{clip}`"]
        for m in minutes:
            r = runs[m].get(clip)
            cells.append(f"{r['test']['psnr']:.2f} ({r['steps']}){other_processor(ten, r)}" if r else "-")
        thirty = runs.get(30, {}).get(clip)
        cells.append(f"{ten['test']['psnr'] - thirty['test']['psnr']:.2f}" if thirty else "-")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    if args[:1] == ["--minutes"]:
        print("\n".join(minutes_table({m: rows_by_clip(RESULTS / f"clips_{m}min.json") for m in (3, 10, 30)})))
        return
    six = Path(args[0]) if args else RESULTS / "clips_6min.json"
    thirty = Path(args[1]) if len(args) > 1 else RESULTS / "clips_30min.json"
    print("\n".join(table(rows_by_clip(six), rows_by_clip(thirty))))


if __name__ == "__main__":
    main()
