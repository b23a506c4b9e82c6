"""Render time of trained avatars at 64, 128 and 256 pixels, and of a dense NerFACE-style renderer
(8x256 MLP, 64 coarse + 64 fine samples on every ray) at 128 pixels, on this machine.

    .venv/bin/python -m benchmarks.bench_render AVATAR [AVATAR ...] [--out benchmarks/results/render.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from models.avatar_io import load_avatar
from models.fields.encoding import encoded_size, frequency_encoding
from models.head.controls import Controls
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.volume import composite, sample_pdf, weights_from_density


def median_seconds(fn, repeats: int = 5) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


class NerfaceMLP(nn.Module):
    """NerFACE's network size: 8 layers of 256 on 10-frequency positions, 76-d expression and a 32-d
    latent, a skip at layer 4 (the weights do not matter for timing)."""

    def __init__(self):
        super().__init__()
        d_in = encoded_size(3, 10) + 76 + 32
        self.first = nn.Sequential(*[m for k in range(4) for m in (nn.Linear(d_in if k == 0 else 256, 256), nn.ReLU())])
        self.second = nn.Sequential(*[m for k in range(4) for m in (nn.Linear(256 + d_in if k == 0 else 256, 256),
                                                                     nn.ReLU())])
        self.out = nn.Linear(256, 4)

    def forward(self, x, cond):
        h_in = torch.cat([frequency_encoding(x, 10), cond.expand(len(x), -1)], -1)
        h = self.first(h_in)
        h = self.second(torch.cat([h, h_in], -1))
        return self.out(h)


def dense_nerface_render(size: int, n_coarse: int = 64, n_fine: int = 64, chunk: int = 8192) -> None:
    torch.manual_seed(0)
    coarse, fine = NerfaceMLP(), NerfaceMLP()
    cond = torch.zeros(1, 108)
    R = size * size
    o = torch.zeros(R, 3)
    d = torch.nn.functional.normalize(torch.randn(R, 3), dim=-1)
    with torch.inference_mode():
        for a in range(0, R, chunk // n_coarse * 4):
            b = min(R, a + chunk // n_coarse * 4)
            bins = torch.linspace(0.3, 0.9, n_coarse + 1).expand(b - a, -1)
            t = 0.5 * (bins[:, 1:] + bins[:, :-1])
            pts = (o[a:b, None] + d[a:b, None] * t[..., None]).reshape(-1, 3)
            raw = coarse(pts, cond).reshape(b - a, n_coarse, 4)
            w, rest = weights_from_density(torch.relu(raw[..., 3]), bins.diff(dim=-1))
            t_f = sample_pdf(bins, w, n_fine)
            pts = (o[a:b, None] + d[a:b, None] * t_f[..., None]).reshape(-1, 3)
            raw = fine(pts, cond).reshape(b - a, n_fine, 4)
            w, rest = weights_from_density(torch.relu(raw[..., 3]), torch.full_like(t_f, 0.6 / n_fine))
            composite(w, torch.sigmoid(raw[..., :3]), rest, torch.ones(3))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("avatars", nargs="+", type=Path)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/render.json"))
    p.add_argument("--skip-dense", action="store_true")
    a = p.parse_args()
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    results: dict = {"threads": torch.get_num_threads(), "avatar_ms": {}}
    for path in a.avatars:
        avatar, meta = load_avatar(path)
        name = "+".join(meta["effects"]) or "none"
        for size in (64, 128, 256):
            cam = framing_camera(avatar.head_model.template, 20, 5, fov_y_deg=18.0, width_px=size, height_px=size)
            s = median_seconds(lambda cam=cam, av=avatar: av.render_image(Controls(), cam, raster))
            results["avatar_ms"][f"{name} {size}px"] = round(1e3 * s, 1)
            print(f"avatar {name:24s} {size:4d} px: {1e3 * s:8.1f} ms")
    if not a.skip_dense:
        s = median_seconds(lambda: dense_nerface_render(128), repeats=1)
        results["dense_nerface_style_128px_ms"] = round(1e3 * s, 1)
        print(f"dense NerFACE-style renderer 128 px: {s:.1f} s")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
