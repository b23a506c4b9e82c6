"""The neural render off the window's thread: progressive passes (draft at once, then finer while the
controls rest), the latest request wins (a newer one cancels the pass in flight between ray batches), each
pass's time measured. The worker owns a headless GL context for the rasterizer: the window's context stays
on the window's thread."""

from __future__ import annotations

import contextlib
import os
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from models.avatars.base import Avatar, RenderCancelled
from models.head.controls import Controls
from models.training.metrics import psnr
from render.camera import Camera, framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer


@dataclass(frozen=True)
class Request:
    controls: Controls
    camera: Camera  # at the final size; presets scale it
    passes: tuple[str, ...] = ("draft", "preview")
    frame: int | None = None  # a training frame's codes (timeline), or the mean code
    inspect: bool = False  # also the colour variants behind the shadow and shading buffers


@dataclass
class Result:
    request_id: int
    pass_name: str
    buffers: dict[str, np.ndarray]
    ms: float




@dataclass
class PresetFigures:
    """A quality preset measured on the loaded avatar: time per frame and error against `final`."""

    ms: dict[str, float] = field(default_factory=dict)
    psnr_vs_final: dict[str, float] = field(default_factory=dict)
    size_px: int = 0
    """The image size they were measured at: the avatar's capture's (at most 256 px), else 128."""


def scaled(camera: Camera, scale: float) -> Camera:
    return camera.resized(max(8, round(camera.width_px * scale)), max(8, round(camera.height_px * scale)))


class NeuralWorker:
    """One background thread that renders the latest request."""

    def __init__(self):
        self._cv = threading.Condition()
        self._avatar: Avatar | None = None
        self._request: Request | None = None
        self._id = 0
        self._measure = False
        self.result: Result | None = None
        self.arrived = threading.Event()
        """Set when a pass's pixels are stored: the window's frame pacing wakes on it, so they show at once."""
        self.busy = False
        self.error = ""
        self.figures = PresetFigures()
        self._quit = False
        self._thread = threading.Thread(target=self._run, name="neural-render", daemon=True)
        self._thread.start()

    # ---- the window's side -----------------------------------------------------------------------------
    def set_avatar(self, avatar: Avatar | None, measure: bool = True) -> None:
        with self._cv:
            self._avatar = avatar
            self._id += 1
            self._request = None
            self.result = None
            self.figures = PresetFigures()
            self._measure = measure and avatar is not None
            self._cv.notify()

    def submit(self, request: Request) -> int:
        with self._cv:
            self._id += 1
            self._request = request
            self._cv.notify()
            return self._id

    def close(self) -> None:
        with self._cv:
            self._quit = True
            self._id += 1
            self._cv.notify()
        self._thread.join(timeout=10)

    # ---- the worker's side -----------------------------------------------------------------------------
    def _run(self) -> None:
        # Below the window's thread: the interface keeps its frame rate; rendering takes what is left. (Linux
        # gives each thread its own nice value; the thread pools torch starts from here inherit it.)
        with contextlib.suppress(OSError, AttributeError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 10)
        torch.set_num_threads(1)  # the window keeps the other core (measured: draft 196 -> 173 ms in the window)
        gl = GLContext.headless()
        raster = Rasterizer(gl)
        while True:
            with self._cv:
                while not self._quit and self._request is None and not self._measure:
                    self._cv.wait()
                if self._quit:
                    break
                # Pixels first: a pending request is rendered before the presets are measured, and a new
                # request interrupts a measurement (which then starts again once the controls rest).
                avatar, request_id = self._avatar, self._id
                request, self._request = self._request, None
                measure = request is None and self._measure
            if avatar is None:
                continue
            self.busy = True
            try:
                if request is not None:
                    self._render(avatar, raster, request, request_id)
                elif measure:
                    self._measure_presets(avatar, raster, request_id)
            except RenderCancelled:
                pass
            except Exception as e:  # shown in the window; the studio keeps running
                self.error = f"render failed: {type(e).__name__}: {e}"
            finally:
                self.busy = False
        raster.release()
        gl.release()

    def _stale(self, request_id: int) -> bool:
        """A newer request (or avatar) arrived since request_id."""
        return self._id != request_id

    def _render(self, avatar, raster: Rasterizer, request: Request, request_id: int) -> None:
        qualities = [avatar.presets[name].quality for name in request.passes]
        for i, name in enumerate(request.passes):
            if i + 1 < len(qualities) and qualities[i + 1] == qualities[i]:
                continue  # the bench may choose one setting for two presets: render it once, as the finer
            avatar.apply_preset(name, request.camera.width_px)
            cam = scaled(request.camera, avatar.presets[name].quality.scale)
            t0 = time.perf_counter()
            buffers = avatar.render_image(request.controls, cam, raster, frame=request.frame,
                                          should_stop=lambda: self._stale(request_id), inspect=request.inspect,
                                          chunk_rays=avatar.interactive_chunk_rays)
            ms = 1e3 * (time.perf_counter() - t0)
            with self._cv:
                if self._stale(request_id):
                    return
                self.result = Result(request_id, name, buffers, ms)
                self.error = ""
            self.arrived.set()

    def _measure_presets(self, avatar, raster: Rasterizer, request_id: int) -> None:
        """Each preset's median time over 3 renders of a 3/4 view and its PSNR against `final`, at the size of
        the avatar's capture (a tracked video's 256 px costs four times a synthetic capture's 128)."""
        size = min(avatar.capture_px or 128, 256)
        cam = framing_camera(avatar.rest_vertices(), 25, 5, fov_y_deg=18.0, width_px=size, height_px=size)
        figures = PresetFigures(size_px=size)
        images = {}
        for name in ("final", "preview", "draft"):
            avatar.apply_preset(name, size)
            c = scaled(cam, avatar.presets[name].quality.scale)
            times = []
            for _ in range(3):
                t0 = time.perf_counter()
                images[name] = avatar.render_image(avatar.at_rest(Controls()), c, raster,
                                                   should_stop=lambda: self._stale(request_id),
                                                   chunk_rays=avatar.interactive_chunk_rays)["rgb"]
                times.append(1e3 * (time.perf_counter() - t0))
            figures.ms[name] = float(np.median(times))
            reference = images["final"]
            if images[name].shape != reference.shape:  # compare at the final size (nearest upsampling)
                k = reference.shape[0] // images[name].shape[0]
                images[name] = images[name].repeat(k, 0).repeat(k, 1)
            figures.psnr_vs_final[name] = float("inf") if name == "final" else psnr(images[name], reference)
        with self._cv:
            if not self._stale(request_id):
                self.figures = figures
                self._measure = False
