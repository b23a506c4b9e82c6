"""What the studio shows, as one value (Session) apart from widgets: the open avatar's files and its capture, the
controls as the sliders hold them, the orbit camera, the display settings, the timeline, the messages. Plain
state and conversions, no GL, no imgui; panels change it only through app/studio/actions.py."""

from __future__ import annotations

import copy
import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.animation import Animation
from app.sliders import Sliders, View
from models.avatars.card import AvatarCard
from models.avatars.checkpoint import read_meta
from models.avatars.registry import read_card
from models.capture.dataset import CaptureSplit, DatasetError, load_split
from models.capture.frames import frame_camera
from models.head.controls import Controls
from render.camera import Camera

RECENT_FILE = Path.home() / ".config" / "avatar-studio" / "recent.json"


LIVE_MAX_PX = 256
"""The largest neural render the studio renders live: 256 px take four times 128's time (README: 'all' 617 ms
at 256 px on this machine)."""


@dataclass
class Display:
    """What the viewport shows and how the neural render refines."""

    buffer: str = "rgb"
    """The neural buffer on screen (viewport.BUFFERS)."""
    guide_pass: str = "shaded"
    wireframe: bool = False
    landmarks: bool = False
    layout: str = "beside"
    """beside: guide and render side by side; over: the guide over the render; render: the render alone."""
    overlay_alpha: float = 0.5
    shown_px: int = 160
    """How large the viewport shows the render (pixels, square), as the window's size leaves room for."""

    @property
    def neural_size(self) -> int:
        """The neural render's size at the final preset: the size it is shown at (a multiple of 8, at least 64),
        up to LIVE_MAX_PX, beyond which it is shown scaled up (linear filtering)."""
        return int(min(max(64, self.shown_px // 8 * 8), LIVE_MAX_PX))
    refine_to: str = "final"
    """The last pass the viewport refines to while the controls rest."""
    live_pass: str = "auto"
    """The pass a live pose renders: auto (the finest that keeps up: app/studio/neural.py, live_pass), or a preset's
    name (that one, however long it takes)."""
    live_guide: bool = False
    """Whether the guide is drawn anew for every live pose. Off, it holds the pose it had when live driving began
    (and follows again when it stops): on a software GL the guide's draw (about 27 ms at 381 px, its shadow map
    included) shares the cores with the render, and with it the avatar's pixels came 187 ms after the camera's
    frame where without it they came in 135 (docs/live.md)."""


@dataclass
class AvatarFiles:
    """An avatar folder as read (off the window's thread): what it says of the avatar, avatar.json, its test metrics
    and the capture it was trained on, where that is still there. The window reads no weights and builds no network
    (the render process loads the avatar)."""

    folder: Path
    avatar: AvatarCard
    meta: dict
    metrics: dict | None = None
    capture: CaptureSplit | None = None
    capture_note: str = ""


def read_avatar_folder(folder: str | Path) -> AvatarFiles:
    """Read an avatar folder (CheckpointError etc. propagate with the reason). It only reads, so the studio runs it
    off the window's thread."""
    folder = Path(folder)
    files = AvatarFiles(folder, read_card(folder), read_meta(folder))
    metrics = folder / "eval" / "metrics.json"
    if metrics.is_file():
        try:
            files.metrics = json.loads(metrics.read_text()).get("metrics")
        except (OSError, json.JSONDecodeError):
            files.metrics = None
    prov = files.meta.get("provenance", {})
    for dataset in (prov.get("dataset"), prov.get("dataset_resolved")):  # as given, then absolute
        if not dataset:
            continue
        try:
            files.capture = load_split(dataset, "train")
            files.capture_note = ""
            break
        except DatasetError:
            files.capture_note = (f"No timeline: the capture it was trained on ({Path(dataset).name}) is not on this "
                                  "machine.")
    return files


EXPRESSION_GROUPS = {"brows": ("brow",), "eyes": ("eye", "blink", "squint"),
                     "mouth": ("mouth", "smile", "frown", "pucker", "jaw", "lip", "stretch"),
                     "cheeks and nose": ("cheek", "nose", "sneer")}


def expression_groups(head) -> dict[str, list[int]]:
    """The head model's expressions by the part of the face their names say they move (the first group whose word
    a name holds; the rest under "other"); unnamed expressions (FLAME's) are one group.

    >>> from models.head.sources import load_builtin
    >>> g = expression_groups(load_builtin()); [load_builtin().expr_names[i] for i in g["brows"]]
    ['browRaise_L', 'browRaise_R', 'browDown_L', 'browDown_R']
    """
    return _groups_of_names(tuple(head.expr_names), head.num_expression)


@functools.lru_cache(maxsize=8)
def _groups_of_names(names: tuple[str, ...], count: int) -> dict[str, list[int]]:
    """expression_groups by the names alone: the Controls panel asks every frame, and the answer is kept without
    keeping a head model (and its bases) alive."""
    groups: dict[str, list[int]] = {}
    for i in range(count):
        name = names[i].lower() if i < len(names) else ""
        group = next((g for g, words in EXPRESSION_GROUPS.items() if any(w in name for w in words)),
                     "other" if name else "expression")
        groups.setdefault(group, []).append(i)
    return groups


@dataclass
class Live:
    """Live driving: what drives the sliders (a camera's index or a video file), the frame behind the sliders now,
    and the performance being recorded."""

    source: str = ""
    running: bool = False
    message: str = ""
    """Why it stopped (the video ended, no camera there): shown in the Live panel."""
    index: int = -1
    """The source frame whose pose the sliders hold (-1: none yet)."""
    stamp: float | None = None
    """When that frame came (time.perf_counter); taken by the render request that shows it."""
    recording: bool = False
    record_start: float | None = None
    """The first recorded pose's frame time: the recording's 0 s."""
    recorded: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    """Channel -> keys (seconds from the first recorded pose, value): the animation being recorded."""


@dataclass
class History:
    """Undo and redo of the sliders and the camera. One change is one step back: a slider dragged through many
    values is one change, as long as the same slider keeps moving (under GESTURE_S between its values)."""

    undo: list[tuple[Sliders, View]] = field(default_factory=list)
    redo: list[tuple[Sliders, View]] = field(default_factory=list)
    gesture: object = None
    last_s: float = -math.inf

    LIMIT = 200
    GESTURE_S = 1.0

    def remember(self, sliders: Sliders, view: View, gesture: object, now: float) -> None:
        """Before a change: keep the state it changes, unless it continues the change before it."""
        continues = gesture is not None and gesture == self.gesture and now - self.last_s < self.GESTURE_S
        self.gesture, self.last_s = gesture, now
        if continues:
            return
        self.undo.append((copy.deepcopy(sliders), copy.deepcopy(view)))
        del self.undo[:-self.LIMIT]
        self.redo.clear()

    def step(self, back: bool, sliders: Sliders, view: View) -> tuple[Sliders, View] | None:
        """The state one change back (or forward, after an undo); None where there is none."""
        source, other = (self.undo, self.redo) if back else (self.redo, self.undo)
        if not source:
            return None
        other.append((copy.deepcopy(sliders), copy.deepcopy(view)))
        self.gesture = None
        return source.pop()


@dataclass
class Session:
    """Everything the studio shows, as one value: the open avatar and its capture, the sliders, the camera, the
    display settings, the timeline, the messages. Panels draw from it and change it only through actions
    (app/studio/actions.py) that the application applies."""

    files: AvatarFiles | None = None
    sliders: Sliders = field(default_factory=lambda: Sliders(np.zeros(0, np.float32)))
    view: View = field(default_factory=View)
    display: Display = field(default_factory=Display)
    timeline_frame: int = -1
    """-1: the sliders' own controls; k: capture frame k."""
    dirty: bool = True
    """The neural render is out of date: the application submits a new request."""
    opening: Path | None = None
    """A folder being read in the background."""
    errors: list[str] = field(default_factory=list)
    job_message: str = ""
    """Why the Jobs panel's last request was refused (shown there, beside the form); "" once one is queued."""
    animation: Animation = field(default_factory=Animation)
    """The keyframes of the sliders and the camera (app/animation.py): keyed, played and exported in the Export
    panel's Animation tab."""
    anim_time: float = 0.0
    """Where on the animation the sliders are, seconds."""
    playing: bool = False
    history: History = field(default_factory=History)
    poses: dict[str, dict[str, float]] = field(default_factory=dict)
    """The open avatar's named poses (app/studio/poses.py)."""
    live: Live = field(default_factory=Live)

    @property
    def avatar(self) -> AvatarCard | None:
        return None if self.files is None else self.files.avatar

    @property
    def folder(self) -> Path | None:
        return None if self.files is None else self.files.folder

    @property
    def capture(self) -> CaptureSplit | None:
        return None if self.files is None else self.files.capture

    @property
    def name(self) -> str:
        return self.folder.name if self.folder else "(none)"

    @property
    def on_capture_frame(self) -> bool:
        """A capture frame is shown (the timeline), with its own camera and controls."""
        return self.capture is not None and 0 <= self.timeline_frame < len(self.capture.frames)

    def render_camera(self, size: int) -> Camera:
        """The neural render's camera: on the timeline the capture frame's own (its intrinsics scaled to `size`
        across: the render lines up with the captured image), else the orbit camera."""
        cap = self.capture
        if self.on_capture_frame:
            height = max(8, round(size * cap.height / cap.width))
            return frame_camera(cap, cap.frames[self.timeline_frame]).resized(size, height)
        return self.view.camera(self.avatar.rest_vertices(), size, size)

    def render_room(self) -> str | None:
        """The file of the room behind the capture frame shown, where its capture keeps one a frame (the camera
        moved: `track --room`); None: the plate, or the avatar's background colour, as the avatar has it."""
        path = self.capture.frames[self.timeline_frame].extra.get("room_path") if self.on_capture_frame else None
        return None if path is None else str(path)

    def controls(self) -> Controls:
        """What the avatar is shown with: a capture frame's controls on the timeline, else the sliders'."""
        if self.on_capture_frame:
            return self.capture.frames[self.timeline_frame].controls
        return self.avatar.at_rest(self.sliders.controls()) if self.avatar is not None else self.sliders.controls()

    def absent(self, how_to_open: str) -> str:
        """What a panel says while it has no avatar to show: the one being read (the first launch reads the demo for
        seconds: not an error), else `how_to_open`."""
        return f"Opening {self.opening.name}..." if self.opening is not None else how_to_open

    def report(self, message: str) -> None:
        """A message in the window (the last 8 are kept)."""
        self.errors.append(message)
        del self.errors[:-8]


def views_warning(s: Session) -> str:
    """The viewport's warning where the camera looks from farther round the head than the capture did ("" where it
    does not): the orbit camera's yaw about the head (the camera's less the head's) against the avatar's captured
    views. A capture frame on the timeline is shown from its own camera with its own pose, one of the views the
    capture saw, whatever the orbit camera and the sliders hold: never a warning."""
    if s.avatar is None or s.on_capture_frame:
        return ""
    if not s.avatar.views_beyond(s.view.yaw_deg - float(s.sliders.head[0])):
        return ""
    lo, hi = s.avatar.view_range["yaw_deg"]
    return f"beyond the captured views (yaw {lo:.0f} to {hi:.0f} degrees): the avatar never saw this side of the head"


def recent_folders() -> list[str]:
    try:
        items = json.loads(RECENT_FILE.read_text())
        return [s for s in items if isinstance(s, str)][:8]
    except (OSError, json.JSONDecodeError):
        return []


def remember_recent(folder: Path) -> None:
    items = [str(Path(folder).resolve())] + [s for s in recent_folders() if s != str(Path(folder).resolve())]
    try:
        RECENT_FILE.parent.mkdir(parents=True, exist_ok=True)
        RECENT_FILE.write_text(json.dumps(items[:8]))
    except OSError:
        pass  # a read-only home: the recent list is a convenience
