"""Keyframed animation of the studio's sliders and camera: channels keyed in time, played back with linear or
smooth (ease in and out) interpolation, saved as JSON, rendered to video by `avatar-studio animate` and the
studio's Export panel.

The file:

    {"format": "avatar-studio/animation/1", "fps": 30, "duration_s": 4.0, "interpolation": "smooth",
     "tracks": {"jaw.open": [[0, 0], [1.5, 18]], "expression.smile": [[0, 0], [2, 0.8]],
                "head.yaw": [[0, -20], [4, 20]], "camera.yaw": [[0, 20], [4, -20]]}}

Channels: expression.NAME (a head model's expression by name, or by its index), head.yaw|pitch|roll and
neck.yaw|pitch|roll (degrees), jaw.open (degrees), gaze.yaw|pitch (degrees, both eyes), camera.yaw|pitch
(degrees), camera.zoom, camera.fov (degrees). Before its first key a channel holds that key's value, after its
last the last's; channels not keyed keep the values the sliders had."""

from __future__ import annotations

import copy
import itertools
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Literal

import numpy as np

from app.display import buffer_image, resized
from app.sliders import Sliders, View
from models.avatars.rendering import RenderOptions, preset_options, render_image
from models.files import atomic_write_bytes
from models.head.model import HeadModel
from models.ranges import Range
from render.gl.raster import Rasterizer

FORMAT = "avatar-studio/animation/1"
POSE_CHANNELS = {f"{group}.{axis}": (group, k) for group in ("head", "neck")
                 for k, axis in enumerate(("yaw", "pitch", "roll"))}
SLIDER_RANGES = {"expression": (-1.0, 1.5), "jaw.open": (-5.0, 30.0), "gaze": (-30.0, 30.0), "head": (-60.0, 60.0),
                 "neck": (-45.0, 45.0)}
"""The Controls panel's slider ranges (expression weights; degrees)."""
OTHER_CHANNELS = ("jaw.open", "gaze.yaw", "gaze.pitch", "camera.yaw", "camera.pitch", "camera.zoom", "camera.fov")


class AnimationError(ValueError):
    """An animation file or channel that cannot be used; the message names the file and the problem."""


def ease(u: float, interpolation: str) -> float:
    """The share of the way from one key to the next at u in [0,1]: linear, or smooth (3u^2 - 2u^3: at rest at
    each key).

    >>> ease(0.25, "linear"), ease(0.25, "smooth"), ease(0.5, "smooth")
    (0.25, 0.15625, 0.5)
    """
    return u if interpolation == "linear" else u * u * (3.0 - 2.0 * u)


@dataclass(frozen=True)
class Animation:
    fps: Annotated[float, Range(1, 240)] = 30.0
    duration_s: Annotated[float, Range(0, 3600, above=True)] = 4.0
    interpolation: Literal["linear", "smooth"] = "smooth"
    tracks: dict[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)
    """Channel -> keys (time in seconds, value), in time order."""

    @property
    def frames(self) -> int:
        return max(1, round(self.duration_s * self.fps))

    def times(self) -> list[float]:
        return [k / self.fps for k in range(self.frames)]

    def value(self, channel: str, t: float) -> float:
        keys = self.tracks[channel]
        if t <= keys[0][0]:
            return keys[0][1]
        for (t0, v0), (t1, v1) in itertools.pairwise(keys):
            if t <= t1:
                u = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
                return v0 + (v1 - v0) * ease(u, self.interpolation)
        return keys[-1][1]

    def with_key(self, channel: str, t: float, value: float) -> Animation:
        """A copy with a key at t (replacing one at the same time)."""
        key = (round(float(t), 6), round(float(value), 6))  # the sliders' float32, as a person would type it
        keys = [k for k in self.tracks.get(channel, ()) if abs(k[0] - t) > 1e-6] + [key]
        return replace(self, tracks={**self.tracks, channel: tuple(sorted(keys))},
                       duration_s=max(self.duration_s, float(t)))

    def without_key(self, channel: str, t: float) -> Animation:
        keys = tuple(k for k in self.tracks.get(channel, ()) if abs(k[0] - t) > 1e-6)
        tracks = {c: v for c, v in self.tracks.items() if c != channel}
        return replace(self, tracks={**tracks, channel: keys} if keys else tracks)

    def pose_at(self, t: float, sliders: Sliders, view: View, head: HeadModel) -> tuple[Sliders, View]:
        """The sliders and camera at time t: keyed channels set, the rest as given."""
        s, v = copy.deepcopy(sliders), copy.deepcopy(view)
        for channel in self.tracks:
            set_channel(s, v, head, channel, self.value(channel, t))
        return s, v

    def to_json(self) -> dict:
        return {"format": FORMAT, "fps": self.fps, "duration_s": self.duration_s,
                "interpolation": self.interpolation,
                "tracks": {c: [list(k) for k in keys] for c, keys in sorted(self.tracks.items())}}


def channel_value(sliders: Sliders, view: View, head: HeadModel, channel: str) -> float:
    """A channel's value on the sliders and camera now (what a new key takes)."""
    group, _, name = channel.partition(".")
    if channel in POSE_CHANNELS:
        g, k = POSE_CHANNELS[channel]
        return float(getattr(sliders, g)[k])
    if group == "expression":
        return float(sliders.expression[expression_index(head, name)])
    return {"jaw.open": lambda: sliders.jaw_open_deg, "gaze.yaw": lambda: float(sliders.gaze_left[0]),
            "gaze.pitch": lambda: float(sliders.gaze_left[1]), "camera.yaw": lambda: view.yaw_deg,
            "camera.pitch": lambda: view.pitch_deg, "camera.zoom": lambda: view.zoom,
            "camera.fov": lambda: view.fov_deg}[channel]()


def set_channel(sliders: Sliders, view: View, head: HeadModel, channel: str, value: float) -> None:
    group, _, name = channel.partition(".")
    if channel in POSE_CHANNELS:
        g, k = POSE_CHANNELS[channel]
        getattr(sliders, g)[k] = value
    elif group == "expression":
        sliders.expression[expression_index(head, name)] = value
    elif channel == "jaw.open":
        sliders.jaw_open_deg = value
    elif channel in ("gaze.yaw", "gaze.pitch"):
        k = 0 if channel == "gaze.yaw" else 1
        sliders.gaze_linked = True
        sliders.gaze_left[k] = value
        sliders.gaze_right[k] = value
    elif channel == "camera.yaw":
        view.yaw_deg = value
    elif channel == "camera.pitch":
        view.pitch_deg = value
    elif channel == "camera.zoom":
        view.zoom = max(value, 1e-3)
    elif channel == "camera.fov":
        view.fov_deg = value
    else:
        raise AnimationError(f"unknown channel {channel!r}")


def expression_index(head: HeadModel, name: str) -> int:
    if name.isdigit() and int(name) < head.num_expression:
        return int(name)
    try:
        return head.expression_index(name)
    except KeyError:
        raise AnimationError(f"channel expression.{name}: head model '{head.name}' has no expression {name!r}"
                             ) from None


def check_channels(anim: Animation, head: HeadModel, where: str) -> None:
    for channel in anim.tracks:
        group, _, name = channel.partition(".")
        if channel in POSE_CHANNELS or channel in OTHER_CHANNELS:
            continue
        if group != "expression":
            raise AnimationError(f"{where}: unknown channel {channel!r} (expression.NAME, "
                                 f"{', '.join([*POSE_CHANNELS, *OTHER_CHANNELS])})")
        try:
            expression_index(head, name)
        except AnimationError as e:
            raise AnimationError(f"{where}: {e}") from None


def read_format_file(path: Path, fmt: str, kind: str, error: type[Exception], after: str = "") -> dict:
    """A JSON file of the studio's own (its "format" key is fmt), read; `error` naming the file and what is wrong
    with it (a file it cannot read, not JSON, not a KIND), with `after` added (what follows for the user)."""
    try:
        data = json.loads(path.read_text())
    except OSError as e:
        raise error(f"{path}: cannot read it ({e.strerror}){after}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise error(f"{path}: not JSON ({e}){after}") from None
    if not isinstance(data, dict) or data.get("format") != fmt:
        raise error(f"{path}: not {kind} (\"format\": \"{fmt}\" is missing){after}")
    return data


def load_animation(path: str | Path) -> Animation:
    """An animation file, checked: AnimationError naming the file and the first problem."""
    path = Path(path)
    data = read_format_file(path, FORMAT, "an animation", AnimationError)
    try:
        fps, duration = float(data.get("fps", 30.0)), float(data["duration_s"])
        interp = data.get("interpolation", "smooth")
        tracks = {}
        for channel, keys in dict(data.get("tracks", {})).items():
            pairs = sorted((float(t), float(v)) for t, v in keys)
            if not pairs or not all(math.isfinite(t) and math.isfinite(v) for t, v in pairs):
                raise ValueError(f"track {channel!r}: keys must be [time, value] pairs of finite numbers")
            tracks[str(channel)] = tuple(pairs)
    except (KeyError, TypeError, ValueError) as e:
        raise AnimationError(f"{path}: {e}") from None
    if interp not in ("linear", "smooth"):
        raise AnimationError(f"{path}: interpolation {interp!r}: expected linear or smooth")
    if not (1 <= fps <= 240 and 0 < duration <= 3600):
        raise AnimationError(f"{path}: fps {fps:g} and duration_s {duration:g}: need 1-240 fps and 0-3600 s")
    return Animation(fps, duration, interp, tracks)


def save_animation(anim: Animation, path: str | Path) -> None:
    atomic_write_bytes(path, (json.dumps(anim.to_json(), indent=1) + "\n").encode())


def animation_poses(anim: Animation, sliders: Sliders, view: View, head: HeadModel
                    ) -> Iterator[tuple[Sliders, View]]:
    for t in anim.times():
        yield anim.pose_at(t, sliders, view, head)


def all_channels(head: HeadModel) -> list[str]:
    """Every channel a head model's sliders and the camera have."""
    names = [n if n else str(k) for k, n in enumerate(list(head.expr_names) + [""] * head.num_expression)]
    return [f"expression.{n}" for n in names[:head.num_expression]] + [*POSE_CHANNELS, *OTHER_CHANNELS]


def rest_sliders(head: HeadModel, shape: np.ndarray | None = None) -> Sliders:
    s = Sliders(np.zeros(head.num_expression, np.float32))
    if shape is not None:
        s.shape = np.asarray(shape, np.float32)
    return s


def animation_frames(avatar, raster: Rasterizer, anim, size: int, preset: str, on_frame=None, should_stop=None,
                     on_pose=None):
    """(size,size,3) uint8 frames of an animation played on an avatar, from its rest sliders (the preset may render
    fewer pixels: scaled up); on_pose(k, controls) before each frame is rendered."""
    options, px = preset_options(avatar.card, preset, size, RenderOptions(should_stop=should_stop, buffers=()))
    for k, (sliders, view) in enumerate(animation_poses(anim, rest_sliders(avatar.head_model), View(),
                                                        avatar.head_model)):
        cam = view.camera(avatar.card.rest_vertices(), px, px)
        controls = avatar.card.at_rest(sliders.controls())
        if on_pose:
            on_pose(k, controls)
        yield resized(buffer_image(render_image(avatar, cam, controls, options, raster), "rgb"), size)
        if on_frame:
            on_frame(k)
