"""The studio command's options (kept apart from the window code, so other commands start without it)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from models.ranges import Range

STUDIO_HOME = Path(os.environ.get("AVATAR_STUDIO_HOME") or Path.home() / "AvatarStudio").resolve()
"""Where the studio's default output paths point (new avatars, turntables), whatever folder it was started in;
AVATAR_STUDIO_HOME moves it."""


@dataclass(frozen=True)
class StudioConfig:
    avatar: Path | None = None
    """Avatar folder to open (default: the shipped demo avatar)."""
    screenshot: Path | None = None
    """Save a screenshot of the whole window to this PNG after --frames frames, then exit."""
    frames: int = 60
    """Frames before the screenshot (with --screenshot)."""
    script: Path | None = None
    """A JSON list of scripted steps to run (tests, pictures); the window exits when they are done."""
    width: int = 1440
    """The window's width, pixels (the viewport's images grow to fill what the panels leave)."""
    height: int = 900
    """The window's height, pixels."""
    fps_cap: Annotated[float, Range(1.0)] = 60.0
    """The interface's frame rate cap (no display sync here): what is left of the CPU goes to rendering."""
    idle_fps: Annotated[float, Range(0.0)] = 9.0
    """The frame rate once nothing on screen moves on its own (no render in flight, no live performer, no animation
    playing) and the user has not acted for 3 seconds: a job's progress is shown at this rate and the cores go to
    the job; any input wakes the window at once (0: never idle). On a software GL the idle window at fps_cap took
    a whole core."""
    rendering_fps_cap: float = 20.0
    """The cap while the neural render works: on a software GL each of the window's frames takes the cores the
    render needs (measured by benchmarks/bench_studio.py: slider to first pixels against the frame rate)."""
    rendering_window_share: float = 0.5
    """While the neural render works, the window's frames take at most this share of one core (its own CPU time
    per frame, measured as it runs: a large window on a software GL draws fewer frames; a window whose frames cost
    under 25 ms of CPU keeps rendering_fps_cap), and never fewer than 8 frames a second."""


@dataclass(frozen=True)
class LiveConfig(StudioConfig):
    source: str = "0"
    """The performer: a camera's OpenCV device index (0: the first camera) or a video file, played in real time."""
