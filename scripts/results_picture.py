"""Test frames side by side: ground truth, then each effect set's render (from out/results/*/eval)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image


def main() -> None:
    root, out = Path(sys.argv[1]), sys.argv[2]
    names = [n for n in ("none", "shading+specular", "all", "nerface") if (root / n / "eval").is_dir()]
    rows = []
    for k in (0, 12, 24):
        tiles = []
        for i, n in enumerate(names):
            side = np.asarray(Image.open(root / n / "eval" / f"test_{k:04d}.png"))
            w = side.shape[0]
            if i == 0:
                tiles.append(side[:, :w])
            tiles.append(side[:, w:2 * w])
        rows.append(np.concatenate(tiles, 1))
    Image.fromarray(np.concatenate(rows, 0)).save(out, optimize=True)
    print(f"wrote {out}: columns ground truth, {', '.join(names)}")


if __name__ == "__main__":
    main()
