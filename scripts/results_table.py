"""Markdown table of out/results/*/eval/metrics.json (written by scripts/run_results.sh)."""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main() -> None:
    root = Path(sys.argv[1] if len(sys.argv) > 1 else "out/results")
    print("| effects | test PSNR (dB) | SSIM | FaceMSE | normal error (deg) | training | steps | render 128 px (ms) |")
    print("|---|---|---|---|---|---|---|---|")
    for name in ("none", "shading+specular", "all"):
        path = root / name / "eval" / "metrics.json"
        if not path.is_file():
            continue
        r = json.loads(path.read_text())
        m, t = r["metrics"], r["training"]
        normal = f"{m['normal_deg']:.1f}" if "normal_deg" in m else "-"
        print(f"| {name} | {m['psnr']:.2f} | {m['ssim']:.4f} | {m['face_mse']:.5f} | {normal} | "
              f"{t['seconds'] / 60:.1f} min | {t['steps']} | {m['render_ms']:.0f} |")


if __name__ == "__main__":
    main()
