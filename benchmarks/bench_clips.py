"""Every shared clip the way a user runs it: `track` with the defaults (the last tenth held out), `train` with the
defaults for --minutes, `eval` on the held-out frames and on the validation frames (between training frames); a
row a clip with what its tracking report says of it (frames, the face's size in the video and in the dataset, the
landmark error, how its masks were cut, what stands behind its frames). Two runs at a time, one thread each.

    .venv/bin/python -m benchmarks.bench_clips --minutes 30 --work out/clips --out benchmarks/results/clips.json

A clip whose capture or avatar exists in --work is not tracked or trained again; a run of some clips adds its rows to
--out's (of the same --minutes), so the table grows a pair at a time."""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from app.bench import processor
from benchmarks.bench_held_out_views import VIDEOS, capture_of, train_and_measure

CLIPS = ("expressions_d3", "expressions_d19", "talking_hdtf", "more/child_looking_around",
         "more/grimaces_green_screen", "more/man_in_suit", "more/phone_portrait_glasses", "more/portrait_seaside",
         "more/singing_boy", "more/sitting_far_portrait", "more/talking_earrings", "more/wide_room_plants",
         "more/woman_blue_wall")


def clip_row(clip: str, work: Path, minutes: float) -> dict:
    capture = capture_of(clip, work, split="time")
    report = json.loads((capture / "tracking" / "report.json").read_text())
    row = train_and_measure(clip, "default", capture, work, minutes, None)
    plate = report["background_plate"]
    row.update(frames=report["splits"], source_face_px=report["source_face_px"],
               face_px=report["face_width_px"]["median"], landmark_error_px=report["landmark_error_px"],
               masks_by=report.get("masks_by"), room=plate["room"], behind_frames=plate.get("behind_frames"),
               track_s_per_frame=report["seconds_per_frame"], machine=processor())
    return row


def merged(kept: list[dict], rows: list[dict]) -> list[dict]:
    """The rows of a file kept from earlier runs with this run's in place of the same clips', in CLIPS' order
    (clips not in CLIPS after them).

    >>> [r["clip"] for r in merged([{"clip": "more/man_in_suit", "n": 1}, {"clip": "expressions_d3", "n": 1}],
    ...                            [{"clip": "more/man_in_suit", "n": 2}])]
    ['expressions_d3', 'more/man_in_suit']
    >>> merged([{"clip": "more/man_in_suit", "n": 1}], [{"clip": "more/man_in_suit", "n": 2}])[0]["n"]
    2
    """
    by_clip = {r["clip"]: r for r in kept} | {r["clip"]: r for r in rows}
    return sorted(by_clip.values(), key=lambda r: (CLIPS.index(r["clip"]) if r["clip"] in CLIPS else len(CLIPS)))


def table(rows: list[dict]) -> str:
    lines = ["| clip | frames (train/val/test) | face in the video / dataset (px) | landmark error (median / p95 px) "
             "| room | steps | validation PSNR | held-out PSNR | the person alone | SSIM | FaceMSE | ms a frame |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        f, le, t, v = r["frames"], r["landmark_error_px"], r["test"], r["val"]
        lines.append(f"| `{r['clip']}` | {f['train']}/{f['val']}/{f['test']} | {r['source_face_px']:.0f} / "
                     f"{r['face_px']:.0f} | {le['median']:.2f} / {le['p95']:.2f} | {r['room']} | {r['steps']} | "
                     f"{v['psnr']:.2f} | **{t['psnr']:.2f}** | {t.get('psnr_person', float('nan')):.2f} | "
                     f"{t['ssim']:.3f} | {t['face_mse']:.4f} | {t['render_ms']:.0f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", nargs="+", default=list(CLIPS), help="as named under ../shared/data/video/")
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--work", type=Path, default=Path("out/clips"))
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/clips.json"))
    ap.add_argument("--parallel", type=int, default=2)
    args = ap.parse_args(argv)
    if not VIDEOS.is_dir():
        raise SystemExit(f"{VIDEOS}: the shared clips are not there")
    args.work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with ThreadPoolExecutor(args.parallel) as pool:
        rows = list(pool.map(lambda clip: clip_row(clip, args.work, args.minutes), args.clips))
    if args.out.is_file():  # a run of some clips adds to the file: the other clips' rows stay
        kept = json.loads(args.out.read_text())
        if kept.get("minutes") == args.minutes:
            rows = merged(kept["rows"], rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"minutes": args.minutes, "rows": rows}, indent=1) + "\n")
    print(table(rows))
    print(f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
