"""What an avatar folder says of its avatar beside the weights (avatar.json, presets.json): where its capture held
the head, the views it saw, its presets, the buffers it renders. The trainer writes it; the registry reads it with
the avatar (`Avatar.card`), and the studio's window reads it alone (registry.read_card), without building the
network: the window poses the guide mesh, frames cameras and offers buffers, and the render process renders."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from models.avatars.quality import BUILTIN_PRESETS, Preset
from models.head.controls import Controls
from models.head.head import Head
from models.head.model import HeadModel
from render.camera import TURNTABLE_ELEVATION_DEG, TURNTABLE_FOV_DEG, Camera, turntable_camera


def builtin_presets() -> dict[str, Preset]:
    return {k: Preset(q) for k, q in BUILTIN_PRESETS.items()}


@dataclass(frozen=True)
class AvatarCard:
    """An avatar as avatar.json and presets.json describe it (the defaults: an avatar not read from a folder)."""

    name: str
    """The model's registry name (avatar.json's "model")."""
    head_model: HeadModel
    effects: tuple[str, ...] = ()
    """The lighting effects the avatar models (empty: none)."""
    buffers: tuple[str, ...] = ()
    """The optional buffers it renders by default (Avatar.default_buffers)."""
    inspection: tuple[str, ...] = ()
    """The inspection buffers its effects make meaningful (Avatar.inspection_buffers)."""
    presets: dict[str, Preset] = field(default_factory=builtin_presets)
    """draft/preview/final: those `bench` measured on this avatar (presets.json), else the built-in ones."""
    presets_measured: dict = field(default_factory=dict)
    """Where `bench` measured them (machine, image size); {} for the built-in ones."""
    capture_px: int | None = None
    """The width of the capture's images it was trained on (avatar.json's "image_px"; None: not recorded)."""
    rest_translation: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    """Where its capture held the head (avatar.json "rest_pose": the training frames' mean translation): the field
    reads world positions, so new controls (sliders, turntables, `render`) place the head there."""
    view_range: dict[str, list[float]] | None = None
    """The directions its capture saw the head from (avatar.json's "view_range": yaw_deg and pitch_deg, least and
    most); None: not recorded."""

    @cached_property
    def head(self) -> Head:
        """The head model's skinning (the window poses the guide mesh with it)."""
        return Head(self.head_model)

    def describe_effects(self) -> str:
        return ", ".join(self.effects) or "none"

    def default_buffers(self) -> tuple[str, ...]:
        return self.buffers

    def inspection_buffers(self) -> tuple[str, ...]:
        return self.inspection

    def at_rest(self, controls: Controls) -> Controls:
        """New controls (the sliders', a turntable's) placed where the capture held the head (rest_translation
        added): a capture frame's own controls are already placed and do not come through here."""
        return replace(controls, translation=np.asarray(controls.translation, np.float32) + self.rest_translation)

    def rest_vertices(self) -> np.ndarray:
        """The template where at_rest places it (what cameras frame)."""
        return self.head_model.template + self.rest_translation

    def turntable_camera(self, yaw_deg: float, size_px: int, elevation_deg: float = TURNTABLE_ELEVATION_DEG,
                         zoom: float = 1.0) -> Camera:
        """A square turntable's camera at this yaw (0: in front): the head at rest filling the frame, seen from
        elevation_deg above its centre (render.camera.turntable_camera); zoom 2 is twice as close."""
        return turntable_camera(self.rest_vertices(), yaw_deg, elevation_deg, fov_y_deg=TURNTABLE_FOV_DEG,
                                width_px=size_px, height_px=size_px, zoom=zoom)

    def views_beyond(self, yaw_deg: float, margin_deg: float = 10.0) -> bool:
        """Whether a camera at this yaw (about the head, 0: in front) looks from farther round than the capture
        did (by more than margin_deg): the avatar has not seen that side."""
        if self.view_range is None:
            return False
        lo, hi = self.view_range["yaw_deg"]
        if hi - lo >= 300:
            return False
        yaw = (yaw_deg + 180.0) % 360.0 - 180.0
        return yaw < lo - margin_deg or yaw > hi + margin_deg

    def turntable_sweep_deg(self, margin_deg: float = 10.0) -> float:
        """How far a turntable may swing each side of the front: the captured yaws and a margin (0: a full turn,
        where the capture went round the head or did not record its views)."""
        if self.view_range is None or np.ptp(self.view_range["yaw_deg"]) >= 300:
            return 0.0
        lo, hi = self.view_range["yaw_deg"]
        return float(min(max(abs(lo), abs(hi)) + margin_deg, 180.0))


def card_of(name: str, meta: dict, head_model: HeadModel, effects: tuple[str, ...], buffers: tuple[str, ...],
            inspection: tuple[str, ...], presets: dict[str, Preset], presets_measured: dict) -> AvatarCard:
    """The card avatar.json describes; what it leaves out or holds malformed (an older avatar's) is not recorded."""
    size = meta.get("image_px")
    width = size[0] if isinstance(size, list) and size else None
    rest = meta.get("rest_pose", {}).get("translation") if isinstance(meta.get("rest_pose"), dict) else None
    try:
        t = np.asarray(rest if rest is not None else [0.0, 0.0, 0.0], np.float32)
        rest_translation = t if t.shape == (3,) and np.isfinite(t).all() else np.zeros(3, np.float32)
    except (TypeError, ValueError):
        rest_translation = np.zeros(3, np.float32)
    views = meta.get("view_range")
    try:
        view_range = {k: [float(views[k][0]), float(views[k][1])] for k in ("yaw_deg", "pitch_deg")}
    except (TypeError, KeyError, IndexError, ValueError):
        view_range = None  # an older avatar: its views unknown
    return AvatarCard(name, head_model, effects, buffers, inspection, presets,
                      presets_measured, width if isinstance(width, int) and width >= 16 else None, rest_translation,
                      view_range)
