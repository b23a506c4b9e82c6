"""The table of subcommands: name, summary, config dataclass, and the function that runs it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from app import avatar_commands, capture_commands, head_commands
from app.bench import BenchConfig, run_bench
from app.reenact import ReenactConfig, run_reenact
from app.studio.config import StudioConfig
from app.track import TrackConfig, run_track
from app.turntable import TurntableConfig
from models.capture.synthetic import SynthConfig
from models.training.prior import PriorTrainConfig
from models.training.trainer import TrainConfig


def run_studio(cfg: StudioConfig) -> int:
    """The window's code (imgui, glfw) loads only for the studio command."""
    from app.studio.app import run_studio as run

    return run(cfg)


@dataclass(frozen=True)
class Command:
    name: str
    summary: str
    config: type
    run: Callable[[object], int | None]
    positional: tuple[str, ...] = ()


COMMANDS = (
    Command("studio", "Open the studio window on an avatar (the shipped demo avatar by default).",
            StudioConfig, run_studio, positional=("avatar",)),
    Command("preview", "Render a head model with given controls to a PNG, headless.",
            head_commands.PreviewConfig, head_commands.run_preview),
    Command("mesh", "Write the posed guide mesh as OBJ or PLY, in the head model's vertex order.",
            head_commands.MeshConfig, head_commands.run_mesh),
    Command("synth", "Render a synthetic capture of a head model under a lighting scene, with ground truth.",
            SynthConfig, capture_commands.run_synth),
    Command("corpus", "Render many people's synthetic multi-view captures: the universal prior's training corpus.",
            capture_commands.CorpusConfig, capture_commands.run_corpus),
    Command("dataset", "Validate a capture dataset (ours, NerFACE's or IMavatar's) and summarise its splits.",
            capture_commands.DatasetConfig, capture_commands.run_dataset, positional=("dataset",)),
    Command("track", "Turn a video of one face into a capture dataset: landmarks, head-model fit, masks, report.",
            TrackConfig, run_track, positional=("video",)),
    Command("train", "Train an avatar on a capture (in the background of a terminal: a progress bar).",
            TrainConfig, avatar_commands.run_train, positional=("dataset",)),
    Command("prior-train", "Train the universal prior (paper 002) on a corpus of identity captures; under torchrun, "
            "on every process it starts (gloo on CPUs, NCCL on GPUs).", PriorTrainConfig,
            avatar_commands.run_prior_train, positional=("corpus",)),
    Command("personalize", "Make a person's avatar from a short scan with the universal prior: neutral maps, "
            "then minutes of fine-tuning.", avatar_commands.PersonalizeConfig, avatar_commands.run_personalize,
            positional=("scan",)),
    Command("eval", "Measure an avatar on a capture split: metrics.json and side-by-side images.",
            avatar_commands.EvalConfig, avatar_commands.run_eval, positional=("avatar", "dataset")),
    Command("render", "Render an avatar with given controls and camera to a PNG.",
            avatar_commands.RenderCommandConfig, avatar_commands.run_render, positional=("avatar",)),
    Command("turntable", "Render an avatar from a camera circling it to an H.264 mp4 and PNG frames.",
            TurntableConfig, avatar_commands.run_turntable, positional=("avatar",)),
    Command("animate", "Render a keyframed animation (sliders and camera, JSON) of an avatar to an H.264 mp4 and PNG "
            "frames.", avatar_commands.AnimateConfig, avatar_commands.run_animate,
            positional=("avatar", "animation")),
    Command("reenact", "Drive an avatar from a performance video: track it, carry its expressions, jaw, gaze and head "
            "turns (relative to the driver's neutral frame) onto the avatar; an mp4 side by side and the animation.",
            ReenactConfig, run_reenact, positional=("avatar", "video")),
    Command("export-mesh", "Write an avatar as a coloured mesh (PLY or OBJ with vertex colours) for "
            "Blender and game engines.", avatar_commands.ExportMeshConfig, avatar_commands.run_export_mesh,
            positional=("avatar",)),
    Command("bench", "Measure what accuracy costs in time: render settings, effect sets, training curves, the "
            "dense NerFACE renderer; charts, and presets chosen from the Pareto front.", BenchConfig, run_bench),
)
