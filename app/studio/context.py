"""What a panel is given each frame: the Session to draw from, `act` to change it, and read-only views of the
application's workers (the neural render, training jobs, exports) and its own timing."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from app.jobs import JobQueue
from app.studio.actions import Action, Command
from app.studio.exporting import Exporter
from app.studio.live import LiveFigures
from app.studio.neural import NeuralWorker
from app.studio.session import Session


@dataclass
class PanelContext:
    session: Session
    act: Callable[[Action | Command], None]
    """Apply an action (or have the application carry out a command)."""
    worker: NeuralWorker
    jobs: JobQueue
    exporter: Exporter
    fps: float = 0.0
    """The interface's frame rate."""
    gui_ms: float | None = None
    """Median time of the window's own Python code a frame."""
    latency_ms: float | None = None
    """Slider to first neural pixels, for the latest request."""
    latency_from: str = "slider"
    """What latency_ms counts from: "slider" (a change), or "opening" (the avatar's first pixels)."""
    live: LiveFigures | None = None
    """Live driving's figures, while a source drives the avatar."""
