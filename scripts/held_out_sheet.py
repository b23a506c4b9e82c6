"""Held-out frames of avatars of real videos, truth beside render, as one picture: for each `eval --split test`
folder given (as `eval` writes it: test_K.png is truth, render, error, normals side by side, metrics.json the
figures), the held-out frame whose PSNR is the clip's median (neither its best nor its worst), labelled with the
clip's name and that frame's PSNR; COLUMNS pairs a row.

    .venv/bin/python scripts/held_out_sheet.py OUT.png out/clips30/expressions_d3_default_eval_test ... [--size 128]"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from PIL import Image, ImageDraw


def median_frame(metrics: dict) -> dict:
    """The per-frame record whose PSNR is the median's (the lower middle one of an even count)."""
    frames = sorted(metrics["per_frame"], key=lambda f: f["psnr"])
    return frames[(len(frames) - 1) // 2]


def pair(eval_folder: Path, size: int, name: str) -> Image.Image:
    """Truth beside render of the median frame, size px each, with a caption strip below."""
    metrics = json.loads((eval_folder / "metrics.json").read_text())
    frame = median_frame(metrics)
    strip = Image.open(eval_folder / f"test_{frame['frame']:04d}.png").convert("RGB")
    side = strip.height
    tiles = [strip.crop((k * side, 0, (k + 1) * side, side)).resize((size, size), Image.LANCZOS) for k in (0, 1)]
    caption = 14
    out = Image.new("RGB", (2 * size, size + caption), (255, 255, 255))
    for k, tile in enumerate(tiles):
        out.paste(tile, (k * size, 0))
    ImageDraw.Draw(out).text((3, size + 1), f"{name}  {frame['psnr']:.1f} dB", fill=(0, 0, 0))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("evals", nargs="+", type=Path)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--columns", type=int, default=3, help="pairs a row")
    a = ap.parse_args()
    pairs = []
    for folder in a.evals:
        metrics = json.loads((folder / "metrics.json").read_text())
        pairs.append(pair(folder, a.size, Path(metrics["dataset"]).name))
    rows = -(-len(pairs) // a.columns)
    w, h = pairs[0].size
    sheet = Image.new("RGB", (a.columns * w + (a.columns - 1) * 4, rows * h), (255, 255, 255))
    for k, p in enumerate(pairs):
        sheet.paste(p, ((k % a.columns) * (w + 4), (k // a.columns) * h))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(a.out, optimize=True)
    print(f"wrote {a.out}: {len(pairs)} clips, {sheet.width} x {sheet.height} px")


if __name__ == "__main__":
    main()
