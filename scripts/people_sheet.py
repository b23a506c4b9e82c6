"""Synthetic people from the front, the side and the back (and the open mouth), as the captures draw them: one row
a person, under the sun scene.

    .venv/bin/python scripts/people_sheet.py docs/img/synthetic_people.png \\
        --head ict:../shared/data/ict_facekit/ict_head.npz --people 0 3 5 8 12 --size 192
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from PIL import Image

from models.capture.looks import look_for_identity
from models.capture.scenes import scene_lighting
from models.capture.script import FrameSpec
from models.capture.synthetic import make_sitter
from models.head.sources import load_head
from render.gl.capture import CaptureRenderer
from render.gl.context import GLContext

BACKGROUND = np.array([0.55, 0.58, 0.62])
#: (camera yaw in degrees, jaw channel weight) of each column: front, three-quarter, side, back, mouth open.
VIEWS = ((0.0, 0.0), (40.0, 0.0), (90.0, 0.0), (180.0, 0.0), (-25.0, 1.0))


def srgb(linear: np.ndarray) -> np.ndarray:
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(np.clip(linear, 0, 1), 1 / 2.4) - 0.055)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out")
    p.add_argument("--head", default="builtin")
    p.add_argument("--people", type=int, nargs="+", default=[0, 3, 5, 8, 12], help="identity seeds, one row each")
    p.add_argument("--hair", default=None, help="the same hair style for everyone (default: each seed's own)")
    p.add_argument("--hair-color", default=None)
    p.add_argument("--size", type=int, default=160, help="pixels per picture")
    p.add_argument("--fov-y-deg", type=float, default=22.0, help="a little wider than a capture's, for long hair")
    a = p.parse_args()
    head = load_head(a.head)
    gl = GLContext.headless()
    renderer = CaptureRenderer(gl)
    lighting = scene_lighting("sun")
    rows = []
    for identity in a.people:
        look = look_for_identity(identity, a.hair, a.hair_color)
        sitter = make_sitter(head, identity, look, a.fov_y_deg)
        cells = []
        for yaw, jaw in VIEWS:
            spec = FrameSpec({"jaw": jaw}, 0.0, 0.0, yaw, 5.0)
            with torch.inference_mode():
                mesh, camera, _, _ = sitter.frame(spec, a.size, a.fov_y_deg)
            buf = renderer.render(mesh, camera, lighting, sitter.appearance)
            cells.append(buf.color + BACKGROUND * (1 - buf.coverage[..., None]))
        rows.append(np.concatenate(cells, 1))
        print(f"identity {identity}: {look.hair} {look.hair_color}, skin {look.skin_tone}")
    renderer.release()
    image = (srgb(np.concatenate(rows, 0)) * 255 + 0.5).astype(np.uint8)
    Image.fromarray(image).save(a.out, optimize=True)


if __name__ == "__main__":
    main()
