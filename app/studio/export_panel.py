"""The Export panel: a turntable (frames, elevation, zoom, size, preset, optional talking) to an H.264 mp4
and PNG frames, in a thread with progress and cancel; a screenshot of the viewport."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from imgui_bundle import imgui

from app.studio.actions import CancelExport, ExportTurntable, SaveViewport
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


def draw(ctx: PanelContext) -> None:
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
    if x.message:
        imgui.text_wrapped(x.message)
