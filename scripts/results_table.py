"""Markdown table of out/results/*/eval/metrics.json (written by scripts/run_results.sh). NerFACE is
evaluated on every third test frame (it takes about half a minute a frame here), so the table also gives
every model's PSNR and FaceMSE on those same frames."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

NAMES = ("none", "shading+specular", "all", "nerface")


def main() -> None:
    root = Path(sys.argv[1] if len(sys.argv) > 1 else "out/results")
    reports = {n: json.loads((root / n / "eval" / "metrics.json").read_text()) for n in NAMES
               if (root / n / "eval" / "metrics.json").is_file()}
    subset = {r["frame"] for r in reports["nerface"]["per_frame"]} if "nerface" in reports else None
    print("| model | test PSNR (dB) | SSIM | FaceMSE | normal error (deg) | PSNR / FaceMSE on every 3rd test frame "
          "| training | steps | render 128 px (ms) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r in reports.items():
        m, t = r["metrics"], r["training"]
        normal = f"{m['normal_deg']:.1f}" if "normal_deg" in m else "-"
        sub = "-"
        if subset:
            rows = [x for x in r["per_frame"] if x["frame"] in subset]
            sub = f"{np.mean([x['psnr'] for x in rows]):.2f} / {np.mean([x['face_mse'] for x in rows]):.5f}"
        label = "NerFACE" if name == "nerface" else f"CoDyNeRF, {name}"
        frames = f" ({r['frames']} frames)" if name == "nerface" else ""
        print(f"| {label} | {m['psnr']:.2f}{frames} | {m['ssim']:.4f} | {m['face_mse']:.5f} | {normal} | {sub} | "
              f"{t['seconds'] / 60:.1f} min | {t['steps']} | {m['render_ms']:.0f} |")


if __name__ == "__main__":
    main()
