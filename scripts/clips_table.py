"""The README's table of how the defaults do on every shared clip, from the two runs of `benchmarks.bench_clips`
kept in benchmarks/results: a row a clip of the 6-minute run, with the 30-minute run's steps, held-out and
validation PSNR beside it where that clip was run for 30 minutes. SSIM, FaceMSE (the face's pixels) and ms a
capture frame are the longest run's of that clip. A 30-minute run on another processor than the 6-minute run's (a
row's `machine`; rows without one ran on the Intel Xeon of the first runs) has its steps marked with an asterisk.

    .venv/bin/python scripts/clips_table.py [SIX.json [THIRTY.json]]   # prints the markdown table"""

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


def other_processor(row: dict, long: dict | None) -> str:
    """"*" where the 30-minute run ran on another processor than the 6-minute run, else "".

    >>> other_processor({}, {"machine": "AMD EPYC, 2 cores"}), other_processor({}, {}), other_processor({}, None)
    ('*', '', '')
    """
    return "*" if long and long.get("machine", XEON) != row.get("machine", XEON) else ""


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


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    six = Path(args[0]) if args else RESULTS / "clips_6min.json"
    thirty = Path(args[1]) if len(args) > 1 else RESULTS / "clips_30min.json"
    print("\n".join(table(rows_by_clip(six), rows_by_clip(thirty))))


if __name__ == "__main__":
    main()
