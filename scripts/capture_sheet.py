"""Contact sheet of a capture: camera panned left and right (first half of the protocol), head turned
left, right and up (second half), and a held-out test frame; rows image / normals / cast-shadow mask.

    .venv/bin/python scripts/capture_sheet.py DATASET OUT.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image

from models.capture.dataset import load_split
from models.capture.synthetic import read_png16


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset")
    p.add_argument("out")
    a = p.parse_args()
    train, test = load_split(a.dataset, "train"), load_split(a.dataset, "test")
    script = [f["script"] for f in json.loads((Path(a.dataset) / "transforms_train.json").read_text())["frames"]]
    key = lambda name, sign: max(range(len(script)), key=lambda k: sign * script[k][name])
    picks = [train.frames[key("camera_yaw_deg", 1)], train.frames[key("camera_yaw_deg", -1)],
             train.frames[key("head_yaw_deg", 1)], train.frames[key("head_yaw_deg", -1)],
             train.frames[key("head_pitch_deg", 1)], test.frames[0]]
    columns = []
    for f in picks:
        image = np.asarray(Image.open(f.image_path).convert("RGB"))
        mask = np.asarray(Image.open(f.extra["mask_path"]))[..., None] / 255.0
        normals = read_png16(f.extra["normal_path"]) * mask + 0.5 * (1 - mask)
        shadow = np.asarray(Image.open(f.extra["shadow_path"]))[..., None] / 255.0
        shadow_view = 0.25 * mask + 0.75 * shadow  # head in grey, cast shadow in white
        columns.append(np.concatenate([image, (normals * 255).astype(np.uint8),
                                       (np.repeat(shadow_view, 3, 2) * 255).astype(np.uint8)], 0))
    Image.fromarray(np.concatenate(columns, 1)).save(a.out, optimize=True)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
