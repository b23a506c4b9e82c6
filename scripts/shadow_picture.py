"""Cast shadows split off, on test frames of a synthetic sun capture: the image and the image without cast
shadows (the capture's ground truth) and what they take away (x4), then each avatar's render without cast
shadows and what its shadows take away (x4), from `avatar-studio eval` side-by-sides.

    .venv/bin/python scripts/shadow_picture.py DATASET OUT.png NAME=EVAL_DIR [NAME=EVAL_DIR ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from models.capture.dataset import load_split
from models.capture.frames import load_rgb
from models.training.metrics import luminance


def main() -> None:
    dataset, out = Path(sys.argv[1]), Path(sys.argv[2])
    evals = [a.split("=", 1) for a in sys.argv[3:]]
    split = load_split(dataset, "test")
    labels = ["image", "truth without", "truth shadows"]
    labels += [f"{n}: {w}" for n, _ in evals for w in ("without", "shadows")]
    rows = []
    frames = [round(i * (len(split.frames) - 1) * 0.4) for i in range(3)]  # 0, 40% and 80% of the test split
    for k in frames:
        f = split.frames[k]
        image = load_rgb(f.image_path)
        lit = load_rgb(f.extra["unshadowed_path"])
        taken = np.clip((luminance(lit) - luminance(image)) * 4, 0, 1)[..., None].repeat(3, 2)
        tiles = [image, lit, taken]
        for _, folder in evals:
            side = np.asarray(Image.open(Path(folder) / f"test_{k:04d}.png"), np.float32) / 255.0
            w = side.shape[0]
            tiles += [side[:, 4 * w:5 * w], side[:, 5 * w:6 * w]]  # eval's panels 5 and 6
        rows.append(np.concatenate(tiles, 1))
    grid = (np.concatenate(rows, 0) * 255).round().astype(np.uint8)
    w = grid.shape[0] // len(frames)
    header = Image.new("RGB", (grid.shape[1], 16), (255, 255, 255))
    draw = ImageDraw.Draw(header)
    for i, text in enumerate(labels):
        draw.text((i * w + 3, 2), text, fill=(0, 0, 0))
    picture = Image.new("RGB", (grid.shape[1], grid.shape[0] + 16))
    picture.paste(header, (0, 0))
    picture.paste(Image.fromarray(grid), (0, 16))
    picture.save(out, optimize=True)
    print(f"wrote {out}: {', '.join(labels)}")


if __name__ == "__main__":
    main()
