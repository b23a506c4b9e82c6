"""The options of synthetic captures (`synth`, `corpus`), apart from the code that draws them: the command line is
built from them, and `--help` must start without torch or GL."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from models.ranges import Range

SceneName = Literal["ambient", "studio", "sun"]
HairStyle = Literal["none", "crop", "bob", "long"]
HairColorName = Literal["black", "dark_brown", "brown", "blond", "auburn", "grey"]


@dataclass(frozen=True)
class SynthConfig:
    head: str = "builtin"
    """HEAD: builtin, demo, ict:PATH or flame:PATH."""
    scene: SceneName = "sun"
    """ambient: spherical-harmonics light only; studio: plus a soft key light (diffuse shading);
    sun: a hard key light with diffuse shading, specular highlights and cast shadows."""
    frames: Annotated[int, Range(10, 1000000)] = 300
    """Frames of the capture protocol, held-out test frames included (about 10%)."""
    size: Annotated[int, Range(16, 2048)] = 256
    """Image width and height in pixels."""
    seed: int = 0
    """Seed of the expression script and held-out frames; the same seed gives the same images."""
    identity: Annotated[int, Range(0)] = 0
    """Identity: 0 is the model's mean head; K > 0 draws identity coefficients from seed K (ICT: principal
    components, built-in: its shape components), within +-2 standard deviations."""
    light_deg: tuple[float, float] | None = None
    """Key light azimuth and elevation in degrees (azimuth from the front towards the subject's left)."""
    hair: HairStyle | None = None
    """Hair style: crop (short, above the ears), bob (to the jaw), long (to the shoulders) or none (bald); left out,
    the identity chooses (identity 0: crop)."""
    hair_color: HairColorName | None = None
    """Hair colour (brows and lashes take a darker shade of it); left out, the identity chooses (identity 0:
    dark_brown)."""
    out: Path = Path("out/capture")
    """Dataset folder to create (must not exist or be empty)."""
    background: tuple[float, float, float] = (0.55, 0.58, 0.62)  # finite: checked as every float
    """Background colour, linear RGB in [0, 1]."""
    fov_y_deg: Annotated[float, Range(1, 170)] = 18.0
    """Camera field of view, degrees (a portrait lens)."""
    turn_deg: Annotated[float, Range(0, 90)] = 45.0
    """The largest head turn (yaw, either way) of the script, degrees; the camera's pan scales with it (40 at 45).
    20: a capture that sees only the front, as a phone's does."""
    views: Annotated[int, Range(1, 16)] = 1
    """Cameras at once: every frame of the script is drawn from this many cameras spaced evenly round the head (the
    script's first), as a capture dome would (--frames counts the script's frames)."""
