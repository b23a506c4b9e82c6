"""The options of training runs (`train`, `prior-train`), apart from the code that trains: the command line is
built from them, and `--help` must start without torch."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from models.avatars.names import ModelName
from models.ranges import Range


@dataclass(frozen=True)
class TrainConfig:
    dataset: Path
    """Capture folder (transforms_{train,val,test}.json with a head model)."""
    out: Path = Path("out/avatar")
    """Avatar folder: avatar.json, weights, progress.jsonl."""
    effects: str | None = None
    """Lighting effects to model: none, all, or a comma list of shading, specular, shadows (default: all; with
    --resume the checkpoint's, and another set is an error)."""
    model: ModelName | None = None
    """The avatar model (models/avatars/registry.py): codynerf, the NerFACE baseline, primitives (volumetric
    primitives on the guide mesh, decoded once a frame), prior (the universal prior personalised) or whole (both:
    primitives where the video saw the head, the prior beyond); default: a tracked video's avatar is a whole head
    where the universal prior ships (else primitives), a synthetic capture's is codynerf."""
    from_scratch: bool = False
    """Train a tracked video's avatar from nothing alone (primitives), without the universal prior beyond its views."""
    prior: Path | None = None
    """The universal prior a video's avatar starts from (`prior-train`); default: the one that ships, where it is
    of the capture's head model."""
    minutes: Annotated[float, Range(0, 1e6, above=True)] | None = None
    """Time budget; training stops when it is spent (checkpointed)."""
    steps: Annotated[int, Range(1)] | None = None
    """Step budget (instead of, or as well as, --minutes); with neither, 2000 steps."""
    resume: bool = False
    """Continue the checkpoint in --out exactly where it stopped."""
    device: Literal["cpu", "cuda"] = "cpu"
    """Where the networks run."""
    seed: int = 0
    """Seed of initialisation and ray sampling."""
    rays_per_step: Annotated[int, Range(1, 1 << 20)] | None = None
    """Rays a step; default: the model's (1024 codynerf; 256 nerface, each of whose rays costs 128 samples of an
    8x256 MLP)."""
    frames_per_step: Annotated[int, Range(1, 1024)] | None = None
    """Training frames a step draws its rays from (--rays-per-step shared evenly between them); default: the
    model's (2 the volumetric primitives, each frame of a step decoded apart; 4 the others)."""
    model_options: tuple[str, ...] = ()
    """The model's own settings, KEY=VALUE each, the fields of its config (the primitives': grid, voxels,
    code_dim, code_swap, expression_maps, ...: README); the rest keep their defaults."""
    corrections: bool | None = None
    """On a tracked video, learn each training frame's head pose correction (and the primitives' expression
    correction) with the avatar; default: the model's (codynerf on, primitives off: README, Real people)."""
    lr: Annotated[float, Range(0, 1, above=True)] = 5e-3
    """Adam learning rate at the start; it decays tenfold over the run (personalising the prior, left at the
    default: the phone-scan paper's 1e-3, PERSONALIZE_LR; a whole head's is its inside's, its outside always
    personalises at PERSONALIZE_LR)."""
    checkpoint_seconds: Annotated[float, Range(0, above=True)] = 60.0
    """How often to checkpoint."""
    grad_clip: Annotated[float, Range(0, above=True)] = 1.0
    """Largest gradient norm of a step."""


PERSONALIZE_LR = 1e-3
"""Fine-tuning the universal prior on one person (the phone-scan paper's Section 4.2.5)."""


@dataclass(frozen=True)
class PriorTrainConfig:
    corpus: Path
    """A folder of captures, one folder per identity, all of one head model (`avatar-studio corpus`)."""
    people: tuple[Path, ...] = ()
    """More people, a capture each, joining the corpus's: real people's videos through `track` (their rooms are
    composited behind them as `train` does), tracked with the corpus's head model."""
    out: Path = Path("out/prior")
    """The prior's folder: avatar.json, weights, progress.jsonl."""
    minutes: Annotated[float, Range(0, 1e6, above=True)] | None = None
    """Time budget; training stops when it is spent (checkpointed)."""
    steps: Annotated[int, Range(1)] | None = None
    """Step budget (with neither, 2000 steps)."""
    resume: bool = False
    """Continue the checkpoint in --out exactly where it stopped (--steps and --minutes count the whole run)."""
    effects: str = "none"
    """Lighting effects the prior models (the corpus's captures must record the key light for more than none)."""
    device: Literal["cpu", "cuda"] = "cpu"
    """Where the networks run (under torchrun, cuda gives each process the GPU of its local rank)."""
    seed: int = 0
    """Seed of initialisation and of the samples every process draws alike."""
    frames_per_step: Annotated[int, Range(1, 4096)] = 4
    """Samples a step over all processes (dealt round them: a multiple of their number)."""
    rays_per_frame: Annotated[int, Range(1, 1 << 20)] = 512
    """Rays each sample of a step takes from its frame."""
    lr: Annotated[float, Range(0, 1, above=True)] = 2e-3
    """Adam's learning rate at the start; it decays tenfold over the run."""
    grid: Annotated[int, Range(8, 256)] = 16
    """K: the prior's primitives on a K x K chart of the head (a power of two)."""
    voxels: Annotated[int, Range(2, 64)] = 8
    """M: each primitive's grid is M^3 voxels (a power of two)."""
    width: Annotated[int, Range(8, 1024)] = 64
    """Channels of the decoder's first feature maps (halved down to 16 as they grow)."""
    kl: Annotated[float, Range(0)] = 1e-5
    """The expression code's KL weight."""
    model_options: tuple[str, ...] = ()
    """The prior's other settings, KEY=VALUE each, the fields of its config (the primitives': opacity_window,
    keep_size, samples, ...: README); the rest keep the prior's defaults."""
    checkpoint_seconds: Annotated[float, Range(0, above=True)] = 120.0
    """How often rank 0 checkpoints, seconds."""
    grad_clip: Annotated[float, Range(0, above=True)] = 1.0
    """Largest gradient norm of a step."""
