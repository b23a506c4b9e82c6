"""What a panel (or a script step) can do to the studio: actions, applied to the Session by the application.

Actions that change only the Session apply themselves (and are tested without a window); commands need the
application's machinery (threads, job processes, exports) and are carried out by it (app/studio/app.py)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.animation import (
    Animation,
    AnimationError,
    all_channels,
    channel_value,
    check_channels,
    load_animation,
    rest_sliders,
    save_animation,
    set_channel,
)
from app.display import needs_covered
from app.sliders import Sliders, View
from app.studio import poses as pose_file
from app.studio.poses import PosesError, apply_pose, avatar_key, pose_of, read_poses, write_poses
from app.studio.session import AvatarFiles, History, Session, expression_groups
from app.turntable import TurntableConfig


class Action:
    """A change of the Session."""

    def apply(self, s: Session) -> None:
        raise NotImplementedError


class Command:
    """A request the application carries out (it may start threads or processes, and report back through
    actions)."""


class SliderChange(Action):
    """A change of the sliders or the camera by the user: undoable (Session.history)."""

    def apply(self, s: Session) -> None:
        h = s.history
        before = (list(h.undo), list(h.redo), h.gesture, h.last_s)
        h.remember(s.sliders, s.view, self.gesture(), time.monotonic())
        try:
            self.change(s)
        except Exception:  # refused (a group that does not exist): no step to undo
            h.undo, h.redo, h.gesture, h.last_s = before
            raise

    def gesture(self) -> object:
        """Changes with the same gesture in a row are one change (a slider's drag); None: a change of its own."""
        return None

    def change(self, s: Session) -> None:
        raise NotImplementedError


def controls_moved(s: Session) -> None:
    """A slider moved: the sliders' controls are shown again, and rendered anew."""
    s.timeline_frame = -1
    s.dirty = True


# ---- the open avatar ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AvatarOpened(Action):
    """An avatar folder was read: it replaces the open one; sliders neutral at the capture's identity."""

    files: AvatarFiles

    def apply(self, s: Session) -> None:
        f = self.files
        shape = f.capture.frames[0].controls.shape if f.capture and f.capture.frames else np.zeros(0)
        s.files = f
        s.sliders = Sliders(np.zeros(f.avatar.head_model.num_expression, np.float32), shape=np.asarray(shape))
        s.timeline_frame = -1
        s.dirty = True
        s.opening = None
        s.history = History()  # another head's sliders: nothing to go back to
        try:
            s.poses = read_poses(pose_file.POSES_FILE).get(avatar_key(f.folder), {})
        except PosesError as e:
            s.poses = {}
            s.report(str(e))


@dataclass(frozen=True)
class OpenFailed(Action):
    message: str

    def apply(self, s: Session) -> None:
        s.opening = None
        s.report(self.message)


# ---- controls ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SetExpression(SliderChange):
    index: int
    value: float

    def gesture(self) -> object:
        return ("expression", self.index)

    def change(self, s: Session) -> None:
        s.sliders.expression[self.index] = self.value
        controls_moved(s)


@dataclass(frozen=True)
class ResetExpression(SliderChange):
    def change(self, s: Session) -> None:
        s.sliders.expression[:] = 0
        controls_moved(s)


@dataclass(frozen=True)
class SetAngles(SliderChange):
    """Head or neck (yaw, pitch, roll), or an eye's gaze (yaw, pitch), in degrees."""

    which: str  # head, neck, gaze_left, gaze_right
    degrees: tuple[float, ...]

    def gesture(self) -> object:
        return ("angles", self.which)

    def change(self, s: Session) -> None:
        if self.which not in ("head", "neck", "gaze_left", "gaze_right"):
            raise ValueError(f"no angles named {self.which!r}")
        getattr(s.sliders, self.which)[:] = np.asarray(self.degrees, np.float32)
        controls_moved(s)


@dataclass(frozen=True)
class SetJaw(SliderChange):
    degrees: float

    def gesture(self) -> object:
        return "jaw"

    def change(self, s: Session) -> None:
        s.sliders.jaw_open_deg = float(self.degrees)
        controls_moved(s)


@dataclass(frozen=True)
class LinkGaze(SliderChange):
    linked: bool

    def change(self, s: Session) -> None:
        s.sliders.gaze_linked = self.linked
        controls_moved(s)


@dataclass(frozen=True)
class ResetPose(SliderChange):
    """Head and neck back to zero."""

    def change(self, s: Session) -> None:
        s.sliders.head[:] = 0
        s.sliders.neck[:] = 0
        controls_moved(s)


@dataclass(frozen=True)
class ResetGaze(SliderChange):
    def change(self, s: Session) -> None:
        s.sliders.gaze_left[:] = 0
        s.sliders.gaze_right[:] = 0
        controls_moved(s)


@dataclass(frozen=True)
class ShowFrame(Action):
    """The timeline: a capture frame's controls and codes, with the sliders moved to its values (-1: the sliders
    as they are)."""

    frame: int

    def apply(self, s: Session) -> None:
        n = len(s.capture.frames) if s.capture is not None else 0
        s.timeline_frame = int(self.frame) if 0 <= self.frame < n else -1
        if s.timeline_frame >= 0:
            s.sliders = Sliders.of(s.capture.frames[s.timeline_frame].controls, s.avatar.head_model.num_expression)
        s.dirty = True


@dataclass(frozen=True)
class ShowAtSize(Action):
    """The viewport shows the render at this size (the window was resized, the layout changed): render anew at
    it where that changes the render's size."""

    px: int

    def apply(self, s: Session) -> None:
        before = s.display.neural_size
        s.display.shown_px = int(self.px)
        if s.display.neural_size != before:
            s.dirty = True


@dataclass(frozen=True)
class CopyFrameToSliders(SliderChange):
    """The timeline's frame becomes the sliders' controls."""

    def change(self, s: Session) -> None:
        if not s.on_capture_frame:
            return
        s.sliders = Sliders.of(s.capture.frames[s.timeline_frame].controls, s.avatar.head_model.num_expression)
        controls_moved(s)


@dataclass(frozen=True)
class ResetGroup(SliderChange):
    """One group of sliders back to rest: an expression group (expression_groups: "expression:mouth"), or head,
    neck, jaw, gaze, camera."""

    group: str

    def change(self, s: Session) -> None:
        sl = s.sliders
        kind, _, part = self.group.partition(":")
        if kind == "expression" and s.avatar is not None:
            groups = expression_groups(s.avatar.head_model)
            if part and part not in groups:
                raise ValueError(f"no expression group {part!r} (this head has {', '.join(groups)})")
            for i in (groups[part] if part else range(len(sl.expression))):
                sl.expression[i] = 0.0
        elif kind in ("head", "neck"):
            getattr(sl, kind)[:] = 0
        elif kind == "jaw":
            sl.jaw_open_deg = 0.0
        elif kind == "gaze":
            sl.gaze_left[:] = 0
            sl.gaze_right[:] = 0
        elif kind == "camera":
            s.view = View()
        elif kind != "expression":
            raise ValueError(f"no slider group {self.group!r}")
        controls_moved(s)


@dataclass(frozen=True)
class Undo(Action):
    """The sliders and the camera one change back (forward = True: redo)."""

    forward: bool = False

    def apply(self, s: Session) -> None:
        state = s.history.step(not self.forward, s.sliders, s.view)
        if state is None:
            return
        s.sliders, s.view = state
        controls_moved(s)


# ---- named poses -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SavePose(Action):
    """The sliders now (the face's channels, not the camera) as a named pose of the open avatar."""

    name: str

    def apply(self, s: Session) -> None:
        name = self.name.strip()
        if s.avatar is None or not name:
            s.report("a pose needs an open avatar and a name")
            return
        try:
            every = read_poses(pose_file.POSES_FILE)
            mine = every.setdefault(avatar_key(s.folder), {})
            mine[name] = pose_of(s.sliders, s.view, s.avatar.head_model)
            write_poses(every, pose_file.POSES_FILE)
        except PosesError as e:
            s.report(str(e))
            return
        except OSError as e:
            s.report(f"{pose_file.POSES_FILE}: cannot save the pose ({e.strerror})")
            return
        s.poses = mine


@dataclass(frozen=True)
class RecallPose(SliderChange):
    name: str

    def change(self, s: Session) -> None:
        if s.avatar is None or self.name not in s.poses:
            s.report(f"no pose named {self.name!r}")
            return
        apply_pose(s.poses[self.name], s.sliders, s.view, s.avatar.head_model)
        controls_moved(s)


@dataclass(frozen=True)
class DeletePose(Action):
    name: str

    def apply(self, s: Session) -> None:
        if s.folder is None:
            return
        try:
            every = read_poses(pose_file.POSES_FILE)
            every.get(avatar_key(s.folder), {}).pop(self.name, None)
            write_poses(every, pose_file.POSES_FILE)
        except (PosesError, OSError) as e:
            s.report(str(e))
            return
        s.poses = every.get(avatar_key(s.folder), {})


# ---- camera ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SetView(SliderChange):
    """Orbit yaw and pitch, zoom, field of view (degrees); None leaves one as it is."""

    yaw_deg: float | None = None
    pitch_deg: float | None = None
    zoom: float | None = None
    fov_deg: float | None = None

    def gesture(self) -> object:
        return ("view", tuple(k for k in ("yaw_deg", "pitch_deg", "zoom", "fov_deg") if getattr(self, k) is not None))

    def change(self, s: Session) -> None:
        for name in ("yaw_deg", "pitch_deg", "zoom", "fov_deg"):
            value = getattr(self, name)
            if value is not None:
                setattr(s.view, name, float(value))
        s.dirty = True


@dataclass(frozen=True)
class Orbit(SliderChange):
    """A mouse drag of (dx, dy) pixels."""

    dx_px: float
    dy_px: float = 0.0

    def gesture(self) -> object:
        return "orbit"

    def change(self, s: Session) -> None:
        s.view.orbit(self.dx_px, self.dy_px)
        s.dirty = True


@dataclass(frozen=True)
class Pan(SliderChange):
    """A right-drag of (dx, dy) pixels over an image of size_px."""

    dx_px: float
    dy_px: float
    size_px: int

    def gesture(self) -> object:
        return "pan"

    def change(self, s: Session) -> None:
        if s.avatar is None:
            return
        cam = s.view.camera(s.avatar.rest_vertices(), self.size_px, self.size_px)
        s.view.pan_by(self.dx_px, self.dy_px, cam)
        s.dirty = True


@dataclass(frozen=True)
class Zoom(SliderChange):
    wheel: float

    def gesture(self) -> object:
        return "zoom"

    def change(self, s: Session) -> None:
        s.view.zoom_by(self.wheel)
        s.dirty = True


@dataclass(frozen=True)
class ResetView(SliderChange):
    def change(self, s: Session) -> None:
        s.view = View()
        s.dirty = True


# ---- display -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShowBuffer(Action):
    name: str

    def apply(self, s: Session) -> None:
        if not needs_covered(s.display.buffer, self.name):
            s.dirty = True  # render again with the buffers this one is made of (a render makes what it shows)
        s.display.buffer = self.name


@dataclass(frozen=True)
class SetDisplay(Action):
    """Guide pass, wireframe, landmarks, layout, overlay opacity: the guide and the layout, not the render; the
    pass live poses render."""

    changes: dict[str, Any] = field(default_factory=dict)

    def apply(self, s: Session) -> None:
        for name, value in self.changes.items():
            if name not in ("guide_pass", "wireframe", "landmarks", "layout", "overlay_alpha", "live_pass",
                            "live_guide"):
                raise ValueError(f"no display setting {name!r}")
            setattr(s.display, name, value)


@dataclass(frozen=True)
class RefineTo(Action):
    preset: str

    def apply(self, s: Session) -> None:
        s.display.refine_to = self.preset
        s.dirty = True


@dataclass(frozen=True)
class Report(Action):
    message: str

    def apply(self, s: Session) -> None:
        s.report(self.message)


@dataclass(frozen=True)
class ClearMessages(Action):
    def apply(self, s: Session) -> None:
        s.errors.clear()


# ---- commands ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OpenAvatar(Command):
    folder: Path


@dataclass(frozen=True)
class StartTraining(Command):
    dataset: str
    out: str
    model: str | None = "codynerf"
    """None: `train`'s own choice (jobs_panel.MODELS)."""
    effects: str = "all"
    minutes: float | None = None
    steps: int | None = None


@dataclass(frozen=True)
class StartFromVideo(Command):
    video: str
    head: str
    landmarker: str
    out: str
    effects: str = "all"
    minutes: float | None = None
    steps: int | None = None
    size: int = 256
    fps: float | None = None
    model: str | None = None
    """None: train's default for a tracked video (primitives)."""


@dataclass(frozen=True)
class StartReenact(Command):
    """A performance video drives the open avatar (`avatar-studio reenact` as a job)."""

    video: str
    landmarker: str
    out: str
    size: int = 256
    seconds: float | None = None
    """Only the video's first seconds (None: all of it)."""


@dataclass(frozen=True)
class OpenReenactment(Command):
    """A finished reenactment's animation on the timeline (its avatar opened first where another is open)."""

    job_id: int


@dataclass(frozen=True)
class CancelJob(Command):
    job_id: int | None = None
    """None: every job."""


@dataclass(frozen=True)
class ResumeJob(Command):
    job_id: int


@dataclass(frozen=True)
class ExportTurntable(Command):
    """A turntable (cfg.avatar: the open avatar's folder) with the controls shown now."""

    cfg: TurntableConfig


@dataclass(frozen=True)
class CancelExport(Command):
    pass


@dataclass(frozen=True)
class SaveViewport(Command):
    path: Path


# ---- the animation -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class KeyPose(Action):
    """Key, at the animation's time, every channel that is keyed already or is away from rest (a channel's first
    key after the start also keys its rest value at the start, so it moves from rest to the pose)."""

    def apply(self, s: Session) -> None:
        if s.avatar is None:
            return
        head = s.avatar.head_model
        rest_s, rest_v = rest_sliders(head, s.sliders.shape), View()
        anim, t = s.animation, s.anim_time
        for ch in all_channels(head):
            value, rest = channel_value(s.sliders, s.view, head, ch), channel_value(rest_s, rest_v, head, ch)
            if ch not in anim.tracks and abs(value - rest) <= 1e-6:
                continue
            if ch not in anim.tracks and t > 0:
                anim = anim.with_key(ch, 0.0, rest)
            anim = anim.with_key(ch, t, value)
        s.animation = anim


@dataclass(frozen=True)
class DeleteKeys(Action):
    """Remove every channel's key at the animation's time."""

    def apply(self, s: Session) -> None:
        anim = s.animation
        for ch in list(anim.tracks):
            anim = anim.without_key(ch, s.anim_time)
        s.animation = anim


@dataclass(frozen=True)
class SeekAnimation(Action):
    """Go to time t: the keyed channels take their values there (the rest keep the sliders')."""

    t: float

    def apply(self, s: Session) -> None:
        s.anim_time = float(np.clip(self.t, 0.0, s.animation.duration_s))
        if s.avatar is not None and s.animation.tracks:
            s.sliders, s.view = s.animation.pose_at(s.anim_time, s.sliders, s.view, s.avatar.head_model)
            controls_moved(s)


@dataclass(frozen=True)
class PlayAnimation(Action):
    playing: bool

    def apply(self, s: Session) -> None:
        s.playing = self.playing and bool(s.animation.tracks)


@dataclass(frozen=True)
class AnimationTiming(Action):
    duration_s: float
    fps: float
    interpolation: str

    def apply(self, s: Session) -> None:
        s.animation = replace(s.animation, duration_s=float(np.clip(self.duration_s, 0.1, 3600.0)),
                              fps=float(np.clip(self.fps, 1.0, 240.0)),
                              interpolation="linear" if self.interpolation == "linear" else "smooth")
        s.anim_time = min(s.anim_time, s.animation.duration_s)


@dataclass(frozen=True)
class SaveAnimation(Action):
    path: Path

    def apply(self, s: Session) -> None:
        try:
            save_animation(s.animation, self.path)
        except OSError as e:
            s.report(f"{self.path}: cannot save the animation ({e.strerror})")


@dataclass(frozen=True)
class LoadAnimation(Action):
    path: Path

    def apply(self, s: Session) -> None:
        try:
            anim = load_animation(self.path)
            if s.avatar is not None:
                check_channels(anim, s.avatar.head_model, str(self.path))
        except AnimationError as e:
            s.report(str(e))
            return
        s.animation, s.anim_time, s.playing = anim, 0.0, False


@dataclass(frozen=True)
class ExportAnimation(Command):
    """The session's animation of the open avatar to an mp4 (and PNG frames beside it)."""

    out: Path
    size: int = 256
    preset: str = "preview"


# ---- live driving --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StartLive(Command):
    """Drive the open avatar from a camera (its OpenCV index, "0") or a video file played in real time."""

    source: str


@dataclass(frozen=True)
class StopLive(Command):
    pass


@dataclass(frozen=True)
class LiveNeutral(Command):
    """The next face the live source shows becomes the neutral one (the avatar at rest)."""


@dataclass(frozen=True)
class LiveStarted(Action):
    source: str

    def apply(self, s: Session) -> None:
        s.live.source, s.live.running, s.live.message = self.source, True, ""
        s.live.index, s.live.stamp = -1, None


@dataclass(frozen=True)
class LiveStopped(Action):
    """Live driving ended (stopped, the video ended, the source failed: `message` says which); a recording in
    progress is finished onto the timeline."""

    message: str = ""

    def apply(self, s: Session) -> None:
        if s.live.recording:
            StopRecording().apply(s)
        s.live.running, s.live.message, s.live.stamp = False, self.message, None
        if self.message:
            s.report(self.message)


@dataclass(frozen=True)
class LivePose(Action):
    """A tracked frame's channel values (app/animation.py's channels) on the sliders, to be rendered; recorded where
    a recording runs. `stamp`: when the frame came (time.perf_counter, seconds)."""

    channels: dict[str, float]
    stamp: float
    index: int

    def apply(self, s: Session) -> None:
        if s.avatar is None or not s.live.running:
            return
        head = s.avatar.head_model
        for channel, value in self.channels.items():
            set_channel(s.sliders, s.view, head, channel, value)
        s.live.index, s.live.stamp = self.index, self.stamp
        controls_moved(s)
        live = s.live
        if live.recording:
            live.record_start = self.stamp if live.record_start is None else live.record_start
            t = round(self.stamp - live.record_start, 6)
            for channel, value in self.channels.items():
                live.recorded.setdefault(channel, []).append((t, round(float(value), 6)))


@dataclass(frozen=True)
class StartRecording(Action):
    """Keep the live performance from the next pose on."""

    def apply(self, s: Session) -> None:
        if not s.live.running:
            s.report("nothing to record: start live driving first")
            return
        s.live.recording, s.live.record_start, s.live.recorded = True, None, {}


@dataclass(frozen=True)
class StopRecording(Action):
    """The recorded performance becomes the animation on the timeline (one linear key a tracked frame, the format
    `animate` reads), saved to `path` where one is given."""

    path: Path | None = None

    def apply(self, s: Session) -> None:
        live = s.live
        live.recording = False
        keys = live.recorded
        if not keys:
            s.report("nothing recorded: no face was tracked while recording")
            return
        fps = 30.0
        end = max(k[-1][0] for k in keys.values())
        s.animation = Animation(fps=fps, duration_s=round(max(end + 1.0 / fps, 1.0 / fps), 6),
                                interpolation="linear", tracks={c: tuple(k) for c, k in keys.items()})
        s.anim_time, s.playing = 0.0, False
        if self.path is not None:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                s.report(f"{self.path.parent}: cannot make the folder for the recording ({e.strerror})")
                return
            SaveAnimation(self.path).apply(s)
