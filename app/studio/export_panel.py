"""The Export panel: a turntable (frames, elevation, zoom, size, preset, optional talking) to an H.264 mp4
and PNG frames, in a thread with progress and cancel; a screenshot of the viewport; the Animation tab: keyframes
of the sliders and camera, playback, the animation's file and its export."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from imgui_bundle import imgui

from app.studio.actions import (
    AnimationTiming,
    CancelExport,
    DeleteKeys,
    ExportAnimation,
    ExportTurntable,
    KeyPose,
    LoadAnimation,
    PlayAnimation,
    SaveAnimation,
    SaveViewport,
    SeekAnimation,
)
from app.studio.config import STUDIO_HOME
from app.studio.context import PanelContext
from app.turntable import TurntableConfig
from models.avatars.quality import PRESET_NAMES


@dataclass
class ExportForm:
    out: str = field(default_factory=lambda: str(STUDIO_HOME / "turntable.mp4"))
    frames: int = 120
    views_only: bool = True
    """Swing within the capture's views (and 10 degrees) rather than turn all the way round."""
    elevation: float = 5.0
    zoom: float = 1.0
    size: int = 256
    preset: int = 1
    animate: bool = False

    def config(self, avatar: Path) -> TurntableConfig:
        return TurntableConfig(avatar, Path(self.out), frames=max(1, self.frames),
                               sweep_deg=None if self.views_only else 0.0, elevation_deg=self.elevation,
                               zoom=self.zoom, size=max(16, self.size - self.size % 2),
                               preset=list(PRESET_NAMES)[self.preset], animate=self.animate)


FORM = ExportForm()
"""The panel's form (widget state)."""


@dataclass
class AnimationForm:
    out: str = field(default_factory=lambda: str(STUDIO_HOME / "animation.mp4"))
    file: str = field(default_factory=lambda: str(STUDIO_HOME / "animation.json"))
    size: int = 256
    preset: int = 1


ANIM = AnimationForm()


def draw(ctx: PanelContext) -> None:
    if imgui.begin_tab_bar("export_tabs"):
        if imgui.begin_tab_item("Turntable")[0]:
            draw_turntable(ctx)
            imgui.end_tab_item()
        if imgui.begin_tab_item("Animation")[0]:
            draw_animation(ctx)
            imgui.end_tab_item()
        imgui.end_tab_bar()
    if ctx.exporter.message:
        imgui.text_wrapped(ctx.exporter.message)


def draw_animation(ctx: PanelContext) -> None:
    """Keys at a time on the animation's timeline (every channel keyed already or away from rest), scrubbing,
    playback, timing and interpolation, the JSON file, and the export."""
    f, x, s, act = ANIM, ctx.exporter, ctx.session, ctx.act
    anim = s.animation
    imgui.set_next_item_width(-1)
    moved, t = imgui.slider_float("##anim_time", s.anim_time, 0.0, anim.duration_s, "%.2f s")
    if moved:
        act(SeekAnimation(t))
    if imgui.button("Key pose"):
        act(KeyPose())
    if imgui.is_item_hovered():
        imgui.set_tooltip("key, at this time, every slider and camera value that is keyed already or away from rest")
    imgui.same_line()
    if imgui.button("Delete keys"):
        act(DeleteKeys())
    imgui.same_line()
    if imgui.button("Stop" if s.playing else "Play"):
        act(PlayAnimation(not s.playing))
    imgui.same_line()
    times = sorted({k[0] for keys in anim.tracks.values() for k in keys})
    imgui.text(f"{len(anim.tracks)} channels, keys at {', '.join(f'{v:g}' for v in times[:6])}"
               f"{' ...' if len(times) > 6 else ''}" if times else "no keys")
    imgui.set_next_item_width(70)
    ch_d, duration = imgui.input_float("s##dur", anim.duration_s, 0.5, 1.0, "%.1f")
    imgui.same_line()
    imgui.set_next_item_width(70)
    ch_f, fps = imgui.input_float("fps", anim.fps, 1.0, 5.0, "%.0f")
    imgui.same_line()
    imgui.set_next_item_width(80)
    kinds = ["linear", "smooth"]
    ch_i, k = imgui.combo("##interp", kinds.index(anim.interpolation), kinds)
    if ch_d or ch_f or ch_i:
        act(AnimationTiming(duration, fps, kinds[k]))
    imgui.set_next_item_width(200)
    _, f.file = imgui.input_text("##animfile", f.file)
    imgui.same_line()
    if imgui.button("Save##anim"):
        act(SaveAnimation(Path(f.file)))
    imgui.same_line()
    if imgui.button("Load##anim"):
        act(LoadAnimation(Path(f.file)))
    imgui.set_next_item_width(200)
    _, f.out = imgui.input_text("mp4##anim", f.out)
    imgui.set_next_item_width(90)
    _, f.size = imgui.input_int("size##anim", f.size, 32)
    imgui.same_line()
    imgui.set_next_item_width(90)
    _, f.preset = imgui.combo("preset##anim", f.preset, list(PRESET_NAMES))
    if x.running:
        imgui.progress_bar(x.done_frames / max(x.total, 1), imgui.ImVec2(-1, 0), f"{x.done_frames}/{x.total}")
        if imgui.button("Cancel export##anim"):
            act(CancelExport())
    elif imgui.button("Export animation"):
        act(ExportAnimation(Path(f.out), f.size, list(PRESET_NAMES)[f.preset]))


def draw_turntable(ctx: PanelContext) -> None:
    e, x, s, act = FORM, ctx.exporter, ctx.session, ctx.act
    _, e.out = imgui.input_text("mp4", e.out)
    imgui.set_next_item_width(90)
    _, e.frames = imgui.input_int("frames", e.frames)
    imgui.same_line()
    imgui.set_next_item_width(90)
    _, e.size = imgui.input_int("size", e.size, 32)
    imgui.set_next_item_width(90)
    _, e.views_only = imgui.checkbox("captured views only", e.views_only)
    if imgui.is_item_hovered():
        imgui.set_tooltip("swing as far round the head as the capture saw it (and 10 degrees), not a full turn")
    imgui.set_next_item_width(90)
    _, e.elevation = imgui.slider_float("elevation", e.elevation, -45, 45, "%.0f deg")
    imgui.same_line()
    imgui.set_next_item_width(90)
    _, e.zoom = imgui.slider_float("zoom##export", e.zoom, 0.5, 3.0, "%.2f")
    imgui.set_next_item_width(90)
    _, e.preset = imgui.combo("preset", e.preset, list(PRESET_NAMES))
    imgui.same_line()
    _, e.animate = imgui.checkbox("talk while turning", e.animate)
    if x.running:
        imgui.progress_bar(x.done_frames / max(x.total, 1), imgui.ImVec2(-1, 0), f"{x.done_frames}/{x.total}")
        if imgui.button("Cancel export"):
            act(CancelExport())
    elif imgui.button("Export turntable") and s.folder is not None:
        act(ExportTurntable(e.config(s.folder)))
    imgui.same_line()
    if imgui.button("Screenshot viewport"):
        act(SaveViewport(Path(e.out).with_name("viewport.png")))
