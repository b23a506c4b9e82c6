"""The table of subcommands: name, summary, config dataclass, and where the function that runs it lives.

The configs are torch-free (app/configs.py and the configs modules beside them), so that building the command line
(`--help`, a typo) takes a fraction of a second; a command's own module, with torch, OpenCV and GL, is imported
only when that command runs."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

from app.configs import (
    AnimateConfig,
    BenchConfig,
    CorpusConfig,
    DatasetConfig,
    EvalConfig,
    ExportConfig,
    ExportMeshConfig,
    MeshConfig,
    PersonalizeConfig,
    PreviewConfig,
    ReenactConfig,
    RenderCommandConfig,
    TrackConfig,
    TurntableConfig,
)
from app.studio.config import LiveConfig, StudioConfig
from models.capture.configs import SynthConfig
from models.training.configs import PriorTrainConfig, TrainConfig


@dataclass(frozen=True)
class Command:
    name: str
    summary: str
    config: type
    run: str
    """"module:function", the function taking the config and returning the exit status (None: 0)."""
    positional: tuple[str, ...] = ()
    research: bool = False
    """Listed apart in `--help`: for work on the models (the prior's corpus and training, benchmarks)."""
    window: bool = False
    """Opens the studio's window: its process ends as soon as the command returns (app/cli.py end_window_process)."""

    def runner(self) -> Callable[[object], int | None]:
        """The function that runs the command, its module imported now."""
        module, _, function = self.run.partition(":")
        return getattr(importlib.import_module(module), function)


COMMANDS = (
    Command("studio", "Open the studio window on an avatar (the shipped demo avatar by default).",
            StudioConfig, "app.studio.app:run_studio", positional=("avatar",), window=True),
    Command("preview", "Render a head model with given controls to a PNG, headless.",
            PreviewConfig, "app.head_commands:run_preview"),
    Command("mesh", "Write the posed guide mesh as OBJ or PLY, in the head model's vertex order.",
            MeshConfig, "app.head_commands:run_mesh"),
    Command("synth", "Render a synthetic capture of a head model under a lighting scene, with ground truth.",
            SynthConfig, "app.capture_commands:run_synth"),
    Command("corpus", "Render many people's synthetic multi-view captures: the universal prior's training corpus.",
            CorpusConfig, "app.capture_commands:run_corpus", research=True),
    Command("dataset", "Validate a capture dataset (ours, NerFACE's or IMavatar's) and summarise its splits.",
            DatasetConfig, "app.capture_commands:run_dataset", positional=("dataset",)),
    Command("track", "Turn a video of one face into a capture dataset: landmarks, head-model fit, masks, report.",
            TrackConfig, "app.track:run_track", positional=("video",)),
    Command("train", "Train an avatar on a capture (in the background of a terminal: a progress bar).",
            TrainConfig, "app.avatar_commands:run_train", positional=("dataset",)),
    Command("prior-train", "Train the universal prior (Cao et al. 2022) on a corpus of identity captures; under "
            "torchrun, on every process it starts (gloo on CPUs, NCCL on GPUs).", PriorTrainConfig,
            "app.avatar_commands:run_prior_train", positional=("corpus",), research=True),
    Command("personalize", "Make a person's avatar from a short scan with the universal prior: neutral maps, "
            "then minutes of fine-tuning.", PersonalizeConfig, "app.avatar_commands:run_personalize",
            positional=("scan",)),
    Command("eval", "Measure an avatar on a capture split: metrics.json and side-by-side images.",
            EvalConfig, "app.avatar_commands:run_eval", positional=("avatar", "dataset")),
    Command("render", "Render an avatar with given controls and camera to a PNG.",
            RenderCommandConfig, "app.avatar_commands:run_render", positional=("avatar",)),
    Command("turntable", "Render an avatar from a camera circling it to an H.264 mp4 and PNG frames.",
            TurntableConfig, "app.avatar_commands:run_turntable", positional=("avatar",)),
    Command("animate", "Render a keyframed animation (sliders and camera, JSON) of an avatar to an H.264 mp4 and PNG "
            "frames.", AnimateConfig, "app.avatar_commands:run_animate", positional=("avatar", "animation")),
    Command("reenact", "Drive an avatar from a performance video: track it, carry its expressions, jaw, gaze and head "
            "turns (relative to the driver's neutral frame) onto the avatar; an mp4 side by side and the animation.",
            ReenactConfig, "app.reenact:run_reenact", positional=("avatar", "video")),
    Command("live", "Drive an avatar live in the studio from a camera or a video played in real time; record the "
            "performance as an animation.", LiveConfig, "app.studio.app:run_live", positional=("avatar",),
            window=True),
    Command("export-mesh", "Write an avatar as a coloured mesh (PLY or OBJ with vertex colours) for "
            "Blender and game engines.", ExportMeshConfig, "app.avatar_commands:run_export_mesh",
            positional=("avatar",)),
    Command("export", "Write an avatar as a glTF 2.0 binary (.glb) for Blender, Unity and the web: the guide mesh "
            "with the expressions as morph targets, jaw and eyes as a skeleton, a texture baked from the avatar, an "
            "animation.", ExportConfig, "app.export:run_export", positional=("avatar",)),
    Command("bench", "Measure what accuracy costs in time: render settings, effect sets, training curves, the "
            "dense NerFACE renderer; charts, and presets chosen from the Pareto front.", BenchConfig,
            "app.bench:run_bench", research=True),
)
