"""The README's tables from a bench run's results.json: each avatar's Pareto front (time, error against the
most accurate setting, test PSNR and FaceMSE, which presets it took) and the dense renderer beside it.

    .venv/bin/python scripts/bench_table.py out/bench/results.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main() -> None:
    results = json.loads(Path(sys.argv[1]).read_text())
    nf = results["nerface"]
    print(f"Machine: {results['machine']}; {results['image_px']} px; test frames {results['test_frames']}; "
          f"`{results['command']}` ({results['bench_seconds'] / 60:.0f} min).\n")
    print("| effects | setting | ms / frame | PSNR vs most accurate | test PSNR | FaceMSE | preset | NerFACE / this |")
    print("|---|---|---|---|---|---|---|---|")
    for r in results["rows"]:
        if not r["on_front"] and not r.get("presets"):
            continue
        vs = "reference" if r["psnr_vs_reference"] >= 99 else f"{r['psnr_vs_reference']:.1f} dB"
        print(f"| {r['effects']} | {r['label']} | {r['ms']:.0f} | {vs} | {r['psnr']:.2f} | {r['face_mse']:.5f} | "
              f"{', '.join(r.get('presets', []))} | {r['nerface_over']:.0f}x |")
    trained = f", test PSNR {nf['psnr']:.2f} dB, FaceMSE {nf['face_mse']:.5f}" if "psnr" in nf else ""
    print(f"\nNerFACE dense renderer ({nf['setting']}): {nf['ms'] / 1e3:.1f} s a frame{trained}.")
    print("\nTraining curves (test PSNR after N training seconds):\n")
    curves = results["training_curves"]
    if curves:
        seconds = [p["seconds"] for p in next(iter(curves.values()))]
        print("| effects | " + " | ".join(f"{s:.0f} s" for s in seconds) + " |")
        print("|---|" + "---|" * len(seconds))
        for name, curve in curves.items():
            print(f"| {name} | " + " | ".join(f"{p['psnr']:.2f}" for p in curve) + " |")


if __name__ == "__main__":
    main()
