"""The bench's charts: error against time per frame (Pareto front and presets marked, the dense NerFACE
renderer beside them with the ratio), and training curves (test PSNR against training seconds)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt

from models.avatars.quality import pareto

COLOURS = {"none": "tab:gray", "shading+specular": "tab:blue", "all": "tab:red", "primitives none": "tab:olive",
           "primitives all": "tab:green", "primitives shading+specular": "tab:cyan"}


def draw_charts(results: dict, out: Path) -> list[Path]:
    charts = [error_vs_time(results, out / "error_vs_time.png")]
    if results["training_curves"]:
        charts.append(training_curves(results, out / "training_curves.png"))
    return charts


def error_vs_time(results: dict, path: Path) -> Path:
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    rows, nf = results["rows"], results["nerface"]
    panels = (("psnr", "test PSNR against ground truth (dB)"), ("psnr_vs_reference", "PSNR against the most "
                                                                                     "accurate setting (dB)"))
    for ax, (key, label) in zip(axes, panels, strict=True):
        for effects in dict.fromkeys(r["effects"] for r in rows):
            # The reference against itself (an infinite PSNR) is not a point of the right-hand chart.
            mine = [r for r in rows if r["effects"] == effects and (key == "psnr" or r["psnr_vs_reference"] < 99)]
            colour = COLOURS.get(effects, None)
            ax.scatter([r["ms"] for r in mine], [r[key] for r in mine], s=14, color=colour, alpha=0.55,
                       label=f"{effects} (settings)")
            on = pareto([(r["ms"], -r[key]) for r in mine])
            front = sorted((r for r, f in zip(mine, on, strict=True) if f), key=lambda r: r["ms"])
            ax.step([r["ms"] for r in front], [r[key] for r in front], where="post", color=colour, lw=1.4,
                    label=f"{effects}: Pareto front")
            for r in mine:
                for name in r.get("presets", []):
                    ax.annotate(name, (r["ms"], r[key]), textcoords="offset points", xytext=(4, -10), fontsize=7,
                                color=colour)
        if key == "psnr" and "psnr" in nf:
            ax.scatter([nf["ms"]], [nf["psnr"]], marker="X", s=70, color="black", label="NerFACE dense (trained)")
        elif key == "psnr":
            ax.axvline(nf["ms"], color="black", ls="--", lw=1, label="NerFACE dense renderer (time)")
        ax.set_xscale("log")
        ax.set_xlabel(f"ms per {results['image_px']} px frame (log)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
        if key == "psnr":
            finals = [r for r in rows if "final" in r.get("presets", [])]
            ratios = ", ".join(f"{nf['ms'] / r['ms']:.0f}x {r['effects']}" for r in finals)
            ax.set_title(f"NerFACE dense: {nf['ms'] / 1e3:.1f} s a frame = {ratios} at `final`", fontsize=9)
        ax.legend(fontsize=7, loc="center right" if key == "psnr" else "lower right")
    fig.suptitle(f"What accuracy costs in time ({results['machine']})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def training_curves(results: dict, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for effects, curve in results["training_curves"].items():
        ax.plot([p["seconds"] for p in curve], [p["psnr"] for p in curve], marker="o", ms=3,
                color=COLOURS.get(effects), label=effects)
    ax.set_xlabel("training seconds (this machine)")
    ax.set_ylabel("test PSNR (dB)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Training curves on the held-out test frames", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
