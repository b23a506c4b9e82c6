"""Test frames side by side: ground truth, then each run's render (ROOT/RUN/eval/test_K.png, as `eval` writes
them). The synthetic results: `results_picture.py out/results OUT.png`; a real video's:
`results_picture.py out/real/256/expressions_d3 OUT.png --runs none,all --frames spread`."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("root", type=Path)
    parser.add_argument("out")
    parser.add_argument("--runs", default="none,shading+specular,all,nerface", help="run folders, in order")
    parser.add_argument("--frames", default="0,12,24",
                        help="test frames, one row each; spread: the first, the middle and the last")
    args = parser.parse_args()
    names = [n for n in args.runs.split(",") if (args.root / n / "eval").is_dir()]
    if args.frames == "spread":
        n = len(list((args.root / names[0] / "eval").glob("test_*.png")))
        frames = [0, n // 2, n - 1]
    else:
        frames = [int(f) for f in args.frames.split(",")]
    rows = []
    for k in frames:
        tiles = []
        for i, n in enumerate(names):
            side = np.asarray(Image.open(args.root / n / "eval" / f"test_{k:04d}.png"))
            w = side.shape[0]
            if i == 0:
                tiles.append(side[:, :w])
            tiles.append(side[:, w:2 * w])
        rows.append(np.concatenate(tiles, 1))
    Image.fromarray(np.concatenate(rows, 0)).save(args.out, optimize=True)
    print(f"wrote {args.out}: columns ground truth, {', '.join(names)}")


if __name__ == "__main__":
    main()
