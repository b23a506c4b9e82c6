"""Rebuild resources/demo_head/head.npz: the demo's person, one ICT-FaceKit identity (MIT; LICENSE beside the npz).

The light ICT model's neutral head with identity K's coefficients (the ones `synth --identity K` draws) added in, its 53
expression blend shapes, triangles, texture coordinates, the 68 landmarks and the vertex regions: everything the demo
avatar and its capture use, and no identity components (the demo is one person). Loaded as `--head demo`.

    .venv/bin/python scripts/make_demo_head.py ICT_NPZ [--identity K]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from models.capture.synthetic import identity_coefficients
from models.head.ict import load_ict_npz
from models.head.sources import DEMO_HEAD_PATH


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ict_npz", type=Path, help="ICT-FaceKit's light model (ict_head.npz)")
    ap.add_argument("--identity", type=int, default=3, help="identity seed, as `synth --identity`")
    args = ap.parse_args()
    head = load_ict_npz(args.ict_npz)
    shape = identity_coefficients(head, args.identity)
    neutral = head.template + np.einsum("vcs,s->vc", head.shape_basis, shape)
    with np.load(args.ict_npz, allow_pickle=False) as src:
        arrays = {k: src[k] for k in ("triangles", "uv", "triangles_uv", "expr_deltas_m", "expr_names",
                                      "landmarks68", "region_names", "region_ranges")}
    arrays["neutral_m"] = neutral.astype(np.float32)
    arrays["id_deltas_m"] = np.zeros((0, *neutral.shape), np.float16)
    arrays["identity_seed"] = np.array(args.identity)
    DEMO_HEAD_PATH.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(DEMO_HEAD_PATH, **arrays)
    print(f"{DEMO_HEAD_PATH}: {DEMO_HEAD_PATH.stat().st_size / 1e6:.1f} MB (identity {args.identity})")


if __name__ == "__main__":
    main()
