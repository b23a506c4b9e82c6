"""The Export panel: a turntable (frames, elevation, zoom, size, preset, optional talking) to an H.264 mp4
and PNG frames, in a thread with progress and cancel; a screenshot of the viewport."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from imgui_bundle import imgui
from PIL import Image

from app.turntable import TurntableConfig, turntable_frames
from models.avatars.base import RenderCancelled
from models.avatars.quality import PRESET_NAMES
from models.avatars.registry import load_avatar
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.video import write_video

if TYPE_CHECKING:
    from app.studio.app import Studio


@dataclass
class ExportState:
    out: str = "out/turntable.mp4"
    frames: int = 120
    elevation: float = 5.0
    zoom: float = 1.0
    size: int = 256
    preset: int = 1
    animate: bool = False
    done_frames: int = 0
    total: int = 0
    running: bool = False
    message: str = ""
    seconds: float = 0.0
    _cancel: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    def start(self, folder: Path, cfg: TurntableConfig, controls) -> None:
        """Render in a thread with its own copy of the avatar and its own GL context."""
        self._cancel.clear()
        self.running, self.done_frames, self.total, self.message = True, 0, cfg.frames, ""

        def work() -> None:
            t0 = time.perf_counter()
            gl = GLContext.headless()
            try:
                avatar, _ = load_avatar(folder)
                frames = turntable_frames(avatar, Rasterizer(gl), cfg, controls,
                                          on_frame=lambda k: setattr(self, "done_frames", k + 1),
                                          should_stop=self._cancel.is_set)
                write_video(frames, cfg.out, cfg.fps, cfg.out.with_suffix("") if cfg.pngs else None)
                self.seconds = time.perf_counter() - t0
                self.message = f"wrote {cfg.out} ({cfg.frames} frames) in {self.seconds:.1f} s"
            except RenderCancelled:
                self.message = "export cancelled (no mp4 written)"
            except Exception as e:
                self.message = f"export failed: {type(e).__name__}: {e}"
            finally:
                gl.release()
                self.running = False

        self._thread = threading.Thread(target=work, name="export", daemon=True)
        self._thread.start()

    def cancel(self) -> None:
        self._cancel.set()

    def wait(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)


def draw(studio: Studio) -> None:
    e = studio.export
    s = studio.session
    _, e.out = imgui.input_text("mp4", e.out)
    imgui.set_next_item_width(90)
    _, e.frames = imgui.input_int("frames", e.frames)
    imgui.same_line()
    imgui.set_next_item_width(90)
    _, e.size = imgui.input_int("size", e.size, 32)
    imgui.set_next_item_width(90)
    _, e.elevation = imgui.slider_float("elevation", e.elevation, -45, 45, "%.0f deg")
    imgui.same_line()
    imgui.set_next_item_width(90)
    _, e.zoom = imgui.slider_float("zoom##export", e.zoom, 0.5, 3.0, "%.2f")
    imgui.set_next_item_width(90)
    _, e.preset = imgui.combo("preset", e.preset, list(PRESET_NAMES))
    imgui.same_line()
    _, e.animate = imgui.checkbox("talk while turning", e.animate)
    if e.running:
        imgui.progress_bar(e.done_frames / max(e.total, 1), imgui.ImVec2(-1, 0), f"{e.done_frames}/{e.total}")
        if imgui.button("Cancel export"):
            e.cancel()
    elif imgui.button("Export turntable") and s.folder is not None:
        export_turntable(studio)
    imgui.same_line()
    if imgui.button("Screenshot viewport"):
        save_viewport(studio, Path(e.out).with_name("viewport.png"))
    if e.message:
        imgui.text_wrapped(e.message)


def export_turntable(studio: Studio) -> None:
    e = studio.export
    e.frames, e.size = max(1, e.frames), max(16, e.size - e.size % 2)
    cfg = TurntableConfig(studio.session.folder, Path(e.out), e.frames, e.elevation, e.zoom, e.size,
                          list(PRESET_NAMES)[e.preset], e.animate)
    if cfg.out.suffix.lower() != ".mp4":
        studio.report(f"{cfg.out}: the turntable is written as an .mp4")
        return
    e.start(studio.session.folder, cfg, studio.controls())


def save_viewport(studio: Studio, path: Path) -> None:
    """The neural render as shown (its current buffer) beside the guide mesh, as one PNG."""
    img = studio.viewport.neural_image
    if img is None:
        studio.report("nothing rendered yet to save")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(path)
    studio.export.message = f"saved {path}"
