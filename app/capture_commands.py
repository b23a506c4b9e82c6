"""`avatar-studio synth`: a synthetic capture of a head model under a lighting scene."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from app.errors import UserInputError
from app.progress import Progress
from models.capture.dataset import SPLITS, check_images, load_split
from models.capture.synthetic import SynthConfig, synthesize
from models.head.sources import load_head
from render.gl.context import GLContext


def run_synth(cfg: SynthConfig) -> int:
    if cfg.frames < 10:
        raise UserInputError(f"--frames {cfg.frames}: a capture needs at least 10 frames")
    if not 16 <= cfg.size <= 2048:
        raise UserInputError(f"--size {cfg.size}: must be 16..2048 pixels")
    if cfg.identity < 0:
        raise UserInputError(f"--identity {cfg.identity}: must be 0 (mean head) or a positive seed")
    if cfg.out.exists() and (not cfg.out.is_dir() or any(cfg.out.iterdir())):
        raise UserInputError(f"{cfg.out}: already exists and is not empty; choose a new folder")
    head = load_head(cfg.head)
    bar: list[Progress] = []

    def progress(done: int, total: int) -> None:
        if not bar:
            bar.append(Progress("synth", total))
        bar[0].update(done)

    summary = synthesize(cfg, head, GLContext.headless(), progress)
    n = summary["frames"]
    print(f"wrote {cfg.out}: {n['train']} train, {n['val']} val, {n['test']} test frames "
          f"({cfg.scene} scene, {cfg.size}x{cfg.size}) in {summary['seconds']:.1f} s")
    return 0


@dataclass(frozen=True)
class DatasetConfig:
    dataset: Path
    """Capture folder: ours (transforms_*.json with a head model), NerFACE's, or IMavatar's flame_params.json."""


def run_dataset(cfg: DatasetConfig) -> int:
    """Validate every split of a capture (its files, and every image they list opened and measured) and summarise
    it; the first problem ends with exit status 2."""
    for split in SPLITS:
        s = load_split(cfg.dataset, split)
        check_images(s)
        fx = s.intrinsics[0]
        extras = sorted({k for f in s.frames for k in f.extra})
        print(f"{split:5s}: {len(s.frames):4d} frames, {s.width}x{s.height}, f={fx:.1f} px, format {s.source_format}, "
              f"head {s.head_model or 'none (NerFACE baseline only)'}"
              + (f", {', '.join(e.removesuffix('_path') for e in extras)}" if extras else "")
              + (f", lighting: {s.lighting.get('scene')} ({', '.join(s.lighting.get('effects', [])) or 'ambient'})"
                 if s.lighting else ""))
    return 0
