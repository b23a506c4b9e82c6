"""How near the back of an avatar's head comes to the colour its video saw on the head: the avatar at rest seen from
behind (yaw 180, 5 degrees up, 256 px), the mean colour of the upper half of its opaque silhouette (the head, not
the shoulders), against the hair's colour in the capture's least expressive frames (the median of the person's
pixels beyond the head mesh above the eyes: models/avatars/prior/maps.py hair_colour) and the crown's (the weighted
median of the chart's texels 8.5 cm and more above the eyes that those frames saw: crown_colour, in the chart of the
shipped prior placed on the capture's head model); the distance is to the first where the frames show it. The same
for the nape: the silhouette's third quarter from the top, where long hair hangs down the back.

    .venv/bin/python scripts/back_colour.py AVATAR CAPTURE [AVATAR CAPTURE ...]"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from models.avatars.prior.maps import crown_colour, eye_heights, weighted_mean
from models.avatars.registry import SHIPPED_PRIOR, load_avatar, load_prior
from models.avatars.rendering import RenderOptions, render_image
from models.capture.dataset import load_split
from models.head.controls import Controls
from models.training.prior import neutral_views
from render.gl.context import GLContext
from render.gl.raster import Rasterizer


def back_colour(avatar, raster: Rasterizer, size: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(3,) each: the mean colour of the upper half of the avatar's opaque silhouette (opacity > 0.9) seen from
    behind (the back of the head), and of its third quarter from the top (the nape, where long hair hangs)."""
    cam = avatar.card.turntable_camera(180.0, size)
    with torch.inference_mode():
        out = render_image(avatar, cam, avatar.card.at_rest(Controls()), RenderOptions(buffers=()), raster)
    solid = np.asarray(out["opacity"]) > 0.9
    rows = np.nonzero(solid.any(1))[0]
    top, height = rows.min(), rows.max() - rows.min()
    band = lambda a, b: solid & ((np.arange(size) >= top + a * height) & (np.arange(size) < top + b * height))[:, None]
    rgb = np.asarray(out["rgb"])
    return rgb[band(0.0, 0.5)].mean(0), rgb[band(0.5, 0.75)].mean(0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pairs", nargs="+", type=Path, help="AVATAR CAPTURE, as many pairs as wanted")
    a = ap.parse_args()
    if len(a.pairs) % 2:
        ap.error("give each avatar its capture: AVATAR CAPTURE [AVATAR CAPTURE ...]")
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    for folder, capture in zip(a.pairs[::2], a.pairs[1::2], strict=True):
        avatar = load_avatar(folder)[0]
        split = load_split(capture, "train")
        prior = load_prior(SHIPPED_PRIOR, split.head_model)[0]  # its chart: the texels' places on the head model
        views = neutral_views(split, prior, gl)
        mean, total = weighted_mean(views.colours, views.weights)
        crown = crown_colour(mean, total, eye_heights(prior.head_model, prior.sampler))
        head = views.hair if views.hair is not None else crown
        back, nape = back_colour(avatar, raster)
        rgb = lambda c: "-" if c is None else "(" + ", ".join(f"{float(x):.3f}" for x in c) + ")"
        gap = lambda c, head=head: "-" if head is None else f"{np.linalg.norm(c - head):.3f}"
        print(f"{folder}: back of the head {rgb(back)}, hair {rgb(views.hair)} (hanging {views.hair_reach_m:.3f} m "
              f"below the eyes), crown {rgb(crown)}, distance {gap(back)}; nape {rgb(nape)}, distance {gap(nape)}")


if __name__ == "__main__":
    main()
