"""`avatar-studio synth`: a synthetic capture of a head model under a lighting scene; `dataset`; `corpus`: many
people's captures for the universal prior."""

from __future__ import annotations

import shlex
from pathlib import Path

from app.configs import HELD_OUT_FROM, CorpusConfig, DatasetConfig
from app.errors import UserInputError
from app.progress import Progress, progress_callback
from models.capture.dataset import SPLITS, check_images, load_split
from models.capture.scenes import SCENE_EFFECTS
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
    summary = synthesize(cfg, head, GLContext.headless(), progress_callback("synth"))
    n = summary["frames"]
    print(f"wrote {cfg.out}: {n['train']} train, {n['val']} val, {n['test']} test frames "
          f"({cfg.scene} scene, {cfg.size}x{cfg.size}) in {summary['seconds']:.1f} s")
    print(next_train(cfg.out))
    return 0


def next_train(capture: Path) -> str:
    """The line that ends a command that made or checked a capture: what to run next."""
    avatar = capture.with_name(capture.name + "_avatar")
    return f"next: avatar-studio train {shlex.quote(str(capture))} --out {shlex.quote(str(avatar))}"


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
    print(next_train(cfg.dataset))
    return 0


def run_corpus(cfg: CorpusConfig) -> int:
    """`corpus`: many people's synthetic captures for the universal prior (models/training/prior.py)."""
    last = cfg.first + cfg.identities - 1
    if last >= HELD_OUT_FROM:
        raise UserInputError(f"--first {cfg.first} --identities {cfg.identities}: seeds up to {last}, but seeds from "
                             f"{HELD_OUT_FROM} up are the held-out people and never go in a corpus")
    scenes = [s.strip() for s in cfg.scenes.split(",") if s.strip()]
    unknown = [s for s in scenes if s not in SCENE_EFFECTS]
    if not scenes or unknown:
        raise UserInputError(f"--scenes {cfg.scenes}: expected a comma list of {', '.join(SCENE_EFFECTS)}")
    if cfg.out.exists() and (not cfg.out.is_dir() or any(cfg.out.iterdir())):
        raise UserInputError(f"{cfg.out}: already exists and is not empty; choose a new folder")
    head = load_head(cfg.head)
    gl = GLContext.headless()
    bar = Progress("corpus", cfg.identities, unit="people")
    for n, k in enumerate(range(cfg.first, last + 1)):
        synthesize(SynthConfig(head=cfg.head, scene=scenes[k % len(scenes)], frames=cfg.frames, size=cfg.size,
                               seed=k, identity=k, views=cfg.views, out=cfg.out / f"id{k:04d}"), head, gl)
        bar.update(n + 1)
    print(f"wrote {cfg.out}: {cfg.identities} people (seeds {cfg.first}-{last}), {cfg.frames} frames x {cfg.views} "
          f"views each, {cfg.size} px, scenes {', '.join(scenes)}")
    return 0
