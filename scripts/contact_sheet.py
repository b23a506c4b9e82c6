"""Tile PNGs into one row (or a grid of N columns): python scripts/contact_sheet.py OUT.png IN.png ... [--cols N]"""

from __future__ import annotations

import argparse

import numpy as np
from PIL import Image


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("out")
    p.add_argument("images", nargs="+")
    p.add_argument("--cols", type=int, default=0)
    a = p.parse_args()
    tiles = [np.asarray(Image.open(f).convert("RGB")) for f in a.images]
    cols = a.cols or len(tiles)
    h, w = tiles[0].shape[:2]
    rows = -(-len(tiles) // cols)
    sheet = np.zeros((rows * h, cols * w, 3), np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, cols)
        sheet[r * h:(r + 1) * h, c * w:(c + 1) * w] = t[:h, :w]
    Image.fromarray(sheet).save(a.out, optimize=True)


if __name__ == "__main__":
    main()
