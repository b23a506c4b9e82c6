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
from scipy.spatial.transform import Rotation

from app.animation import Animation
from models.avatars.base import Avatar
from models.avatars.registry import load_avatar
from models.capture.dataset import CaptureSplit, DatasetError, load_split
from models.capture.frames import frame_camera
from models.head.controls import Controls
from render.camera import Camera, framing_camera

RECENT_FILE = Path.home() / ".config" / "avatar-studio" / "recent.json"


def euler_to_rotvec(yaw_deg: float, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """Axis-angle (3,) of a head turned by yaw (about +y), then pitch (about +x), then roll (about +z)."""
    return Rotation.from_euler("YXZ", [yaw_deg, pitch_deg, roll_deg], degrees=True).as_rotvec().astype(np.float32)


def rotvec_to_euler(rotvec: np.ndarray) -> np.ndarray:
    """The inverse of euler_to_rotvec, degrees (yaw, pitch, roll)."""
    return Rotation.from_rotvec(np.asarray(rotvec, np.float64)).as_euler("YXZ", degrees=True).astype(np.float32)


@dataclass
class Sliders:
    """The controls as the Controls panel holds them (degrees where a person thinks in degrees)."""

    expression: np.ndarray
    head: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))  # yaw, pitch, roll
    neck: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    jaw_open_deg: float = 0.0
    gaze_linked: bool = True
    gaze_left: np.ndarray = field(default_factory=lambda: np.zeros(2, np.float32))  # yaw, pitch
    gaze_right: np.ndarray = field(default_factory=lambda: np.zeros(2, np.float32))
    shape: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))  # the capture's identity

    def controls(self) -> Controls:
        right = self.gaze_left if self.gaze_linked else self.gaze_right
        return Controls(shape=self.shape, expression=self.expression.copy(),
                        root=euler_to_rotvec(*self.head), neck=euler_to_rotvec(*self.neck),
                        jaw=np.array([math.radians(self.jaw_open_deg), 0, 0], np.float32),
                        gaze_left=euler_to_rotvec(self.gaze_left[0], self.gaze_left[1], 0),
                        gaze_right=euler_to_rotvec(right[0], right[1], 0))

    @staticmethod
    def of(controls: Controls, n_expression: int) -> Sliders:
        """Sliders showing given controls (a capture frame's)."""
        expr = np.zeros(n_expression, np.float32)
        expr[: min(n_expression, len(controls.expression))] = controls.expression[:n_expression]
        gl, gr = rotvec_to_euler(controls.gaze_left), rotvec_to_euler(controls.gaze_right)
        return Sliders(expr, rotvec_to_euler(controls.root), rotvec_to_euler(controls.neck),
                       math.degrees(float(controls.jaw[0])), bool(np.allclose(gl, gr, atol=1e-3)),
                       gl[:2].copy(), gr[:2].copy(), np.asarray(controls.shape, np.float32))


def sliders_json(s: Sliders) -> dict:
    """The sliders as plain numbers (scripted runs' reports)."""
    r = lambda v: [round(float(x), 5) for x in v]
    return {"expression": r(s.expression), "head": r(s.head), "neck": r(s.neck),
            "jaw_open_deg": round(float(s.jaw_open_deg), 5), "gaze_left": r(s.gaze_left), "gaze_right": r(s.gaze_right)}


@dataclass
class View:
    """The orbit camera."""

    yaw_deg: float = 20.0
    pitch_deg: float = 5.0
    zoom: float = 1.0
    fov_deg: float = 18.0
    pan: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))

    def camera(self, vertices: np.ndarray, width: int, height: int) -> Camera:
        return framing_camera(vertices, self.yaw_deg, self.pitch_deg, self.fov_deg, width, height, zoom=self.zoom,
                              target_offset=tuple(self.pan))

    def orbit(self, dx_px: float, dy_px: float) -> None:
        self.yaw_deg = (self.yaw_deg - 0.4 * dx_px + 180) % 360 - 180
        self.pitch_deg = float(np.clip(self.pitch_deg + 0.4 * dy_px, -85, 85))

    def pan_by(self, dx_px: float, dy_px: float, camera: Camera) -> None:
        """Move the target with the mouse, in the camera's plane (about a pixel per pixel at the head)."""
        c2w = np.linalg.inv(camera.view)
        scale = 2 * math.tan(math.radians(camera.fov_y_deg) / 2) * np.linalg.norm(camera.position) / camera.height_px
        self.pan = (self.pan - c2w[:3, 0] * dx_px * scale + c2w[:3, 1] * dy_px * scale).astype(np.float32)

    def zoom_by(self, wheel: float) -> None:
        self.zoom = float(np.clip(self.zoom * 1.1**wheel, 0.25, 8.0))


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


@dataclass
class AvatarFiles:
    """An avatar folder as read (off the window's thread): the avatar, avatar.json, its test metrics and the
    capture it was trained on, where that is still there."""

    folder: Path
    avatar: Avatar
    meta: dict
    metrics: dict | None = None
    capture: CaptureSplit | None = None
    capture_note: str = ""


def read_avatar_folder(folder: str | Path) -> AvatarFiles:
    """Read an avatar folder (CheckpointError etc. propagate with the reason). It only reads, so the studio runs it
    off the window's thread."""
    folder = Path(folder)
    avatar, meta = load_avatar(folder)
    files = AvatarFiles(folder, avatar, meta)
    metrics = folder / "eval" / "metrics.json"
    if metrics.is_file():
        try:
            files.metrics = json.loads(metrics.read_text()).get("metrics")
        except (OSError, json.JSONDecodeError):
            files.metrics = None
    prov = meta.get("provenance", {})
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

    @property
    def avatar(self) -> Avatar | None:
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

    def render_camera(self, size: int) -> Camera:
        """The neural render's camera: on the timeline the capture frame's own (its intrinsics scaled to `size`
        across: the render lines up with the captured image), else the orbit camera."""
        cap = self.capture
        if cap is not None and 0 <= self.timeline_frame < len(cap.frames):
            height = max(8, round(size * cap.height / cap.width))
            return frame_camera(cap, cap.frames[self.timeline_frame]).resized(size, height)
        return self.view.camera(self.avatar.rest_vertices(), size, size)

    def controls(self) -> Controls:
        """What the avatar is shown with: a capture frame's controls on the timeline, else the sliders'."""
        if self.capture is not None and 0 <= self.timeline_frame < len(self.capture.frames):
            return self.capture.frames[self.timeline_frame].controls
        return self.avatar.at_rest(self.sliders.controls()) if self.avatar is not None else self.sliders.controls()

    def report(self, message: str) -> None:
        """A message in the window (the last 8 are kept)."""
        self.errors.append(message)
        del self.errors[:-8]


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
