"""Turntable and animation exports off the window's thread: each in a thread of its own, with its own copy of the
avatar and its own GL context, with progress and cancel; the mp4 appears only when complete."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from app.animation import Animation, animation_frames
from app.turntable import TurntableConfig, turntable_frames
from models.avatars.base import RenderCancelled
from models.avatars.registry import load_avatar
from models.head.controls import Controls
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.video import write_video


class Exporter:
    """One export at a time; its progress is read by the Export panel."""

    def __init__(self):
        self.done_frames = 0
        self.total = 0
        self.running = False
        self.message = ""
        self.seconds = 0.0
        self._cancel = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, cfg: TurntableConfig, controls: Controls) -> None:
        """Render cfg's turntable of cfg.avatar with these controls."""
        self._run(cfg.avatar, cfg.out, cfg.frames, cfg.fps, cfg.pngs,
                  lambda avatar, raster, on_frame: turntable_frames(avatar, raster, cfg, controls, on_frame=on_frame,
                                                                    should_stop=self._cancel.is_set))

    def start_animation(self, folder: Path, anim: Animation, out: Path, size: int, preset: str) -> None:
        """Render an animation of the avatar in `folder` (its frames from the rest sliders, as `animate` does)."""
        self._run(folder, out, anim.frames, anim.fps, True,
                  lambda avatar, raster, on_frame: animation_frames(avatar, raster, anim, size, preset, on_frame,
                                                                    should_stop=self._cancel.is_set))

    def _run(self, folder: Path, out: Path, total: int, fps: float, pngs: bool, frames_of) -> None:
        self._cancel.clear()
        self.running, self.done_frames, self.total, self.message = True, 0, total, ""

        def work() -> None:
            t0 = time.perf_counter()
            gl = GLContext.headless()
            try:
                avatar, _ = load_avatar(folder)
                frames = frames_of(avatar, Rasterizer(gl), lambda k: setattr(self, "done_frames", k + 1))
                write_video(frames, out, fps, out.with_suffix("") if pngs else None)
                self.seconds = time.perf_counter() - t0
                self.message = f"wrote {out} ({total} frames) in {self.seconds:.1f} s"
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
