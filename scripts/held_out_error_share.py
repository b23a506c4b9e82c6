"""Where a real clip's held-out error lies: for each `eval --split test` folder given with its capture, the squared
error of the held-out frames (truth and render as `eval` saved them, 8-bit) split into the face (the tracked face's
pixels, as FaceMSE takes them), the person's outline (a band of EDGE px each side of the capture's mask: hair,
shoulders and collar against the room), the rest of the person (hair, neck, clothes within the outline) and the
room; with each clip's PSNR over the frames and what it would be were the outline's error gone.

    .venv/bin/python scripts/held_out_error_share.py out/clips6 [--runs default] [--edge 4]

reads WORK/NAME (the capture) and WORK/NAME_RUN_eval_test for every NAME tracked there; prints a markdown table."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage

from app.avatar_commands import face_mask_of
from models.capture.dataset import load_split
from models.capture.frames import load_mask

REGIONS = ("face", "outline", "person", "room")


def region_masks(face: np.ndarray, person: np.ndarray, edge: int) -> dict[str, np.ndarray]:
    """Disjoint boolean masks covering the image: the face first, then the band of `edge` px about the person's
    mask's edge, then the person inside it, then the room.

    >>> m = region_masks(np.zeros((1, 9), bool), np.arange(9)[None] < 4, 1)
    >>> [np.flatnonzero(m[k][0]).tolist() for k in REGIONS]
    [[], [3, 4], [0, 1, 2], [5, 6, 7, 8]]
    """
    band = ndimage.binary_dilation(person, iterations=edge) & ~ndimage.binary_erosion(person, iterations=edge,
                                                                                      border_value=1)
    outline = band & ~face
    inner = person & ~face & ~outline
    return {"face": face, "outline": outline, "person": inner, "room": ~(face | outline | inner)}


def clip_shares(capture: Path, evaluated: Path, edge: int) -> dict:
    """The summed squared error of a clip's held-out frames by region, their pixel count, and the PSNRs."""
    sums, pixels = dict.fromkeys(REGIONS, 0.0), 0
    for frame in load_split(capture, "test").frames:
        strip = np.asarray(Image.open(evaluated / f"test_{frame.index:04d}.png").convert("RGB"), np.float64) / 255
        side = strip.shape[0]
        err = ((strip[:, :side] - strip[:, side:2 * side]) ** 2).mean(-1)
        face = face_mask_of(frame, err.shape)
        person = (load_mask(frame.extra["mask_path"]) > 0.5) if "mask_path" in frame.extra else np.zeros_like(face)
        for name, mask in region_masks(face, person, edge).items():
            sums[name] += float(err[mask].sum())
        pixels += err.size
    total = sum(sums.values())
    return {"shares": {k: v / total for k, v in sums.items()}, "psnr": -10 * np.log10(total / pixels),
            "psnr_outline_exact": -10 * np.log10((total - sums["outline"]) / pixels)}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("work", type=Path)
    ap.add_argument("--runs", nargs="+", default=["default"])
    ap.add_argument("--edge", type=int, default=4, help="px each side of the mask's edge that count as its outline")
    args = ap.parse_args(argv)
    print("| clip | run | held-out PSNR (8-bit) | face | outline | rest of the person | room "
          "| PSNR, the outline exact |")
    print("|---|---|---|---|---|---|---|---|")
    for capture in sorted(p.parent for p in args.work.glob("*/transforms_test.json")):
        for run in args.runs:
            evaluated = args.work / f"{capture.name}_{run}_eval_test"
            if not (evaluated / "metrics.json").is_file():
                continue
            r = clip_shares(capture, evaluated, args.edge)
            s = r["shares"]
            print(f"| `{capture.name}` | {run} | {r['psnr']:.2f} | {s['face']:.2f} | {s['outline']:.2f} | "
                  f"{s['person']:.2f} | {s['room']:.2f} | {r['psnr_outline_exact']:.2f} |")


if __name__ == "__main__":
    main()
