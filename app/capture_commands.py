"""`avatar-studio synth`: a synthetic capture of a head model under a lighting scene; `dataset`; `corpus`: many
people's captures for the universal prior."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from app.errors import UserInputError
from app.progress import Progress, progress_callback
from models.capture.dataset import SPLITS, check_images, load_split
from models.capture.scenes import SCENE_EFFECTS
from models.capture.synthetic import SynthConfig, synthesize
from models.head.sources import load_head
from models.ranges import Range
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


HELD_OUT_FROM = 1000
"""Identity seeds from here up are the held-out people every evaluation of the prior uses: never in a corpus."""


@dataclass(frozen=True)
class CorpusConfig:
    out: Path = Path("out/corpus")
    """Folder to create: one capture a person (id0001, id0002, ...)."""
    identities: Annotated[int, Range(1, HELD_OUT_FROM - 1)] = 8
    """People in the corpus: identity seeds --first .. --first + N - 1 (shape, skin tone and features drawn from
    the seed: `synth --identity K`)."""
    first: Annotated[int, Range(1, HELD_OUT_FROM - 1)] = 1
    head: str = "builtin"
    """HEAD: builtin, ict:PATH or flame:PATH (ICT's 100 identity components give the widest spread of faces)."""
    scenes: str = "ambient"
    """Lighting scenes, a comma list; the K-th person is captured under the (K mod n)-th."""
    frames: Annotated[int, Range(10, 100000)] = 60
    """Frames of each person's range-of-motion script (held-out frames included)."""
    views: Annotated[int, Range(1, 16)] = 4
    """Cameras at once on every frame, evenly round the head (the seed's multi-view capture: the prior learns the
    whole head, back and top included, which a monocular scan never shows)."""
    size: Annotated[int, Range(16, 2048)] = 128


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
