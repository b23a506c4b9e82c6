"""The neural render off the window's thread, in a process of its own: progressive passes (draft at once, then
finer while the controls rest), the latest request wins (a newer one cancels the pass in flight between ray
batches), each pass's time measured. The renderer is a separate process (spawned) so that it and the window do
not share Python's interpreter lock: in a thread, the window's frames held it while the render waited, and a
128 px draft of the demo took 173 ms in the window against 115 ms alone on one thread. The renderer reads the
avatar from its folder itself and owns a headless GL context for its rasterizer; the window's context stays on
the window's thread."""

from __future__ import annotations

import contextlib
import functools
import multiprocessing as mp
import os
import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from models.avatars.rendering import RenderOptions, render_image
from models.capture.frames import read_room
from models.head.controls import Controls
from render.camera import Camera, framing_camera


@dataclass(frozen=True)
class Request:
    controls: Controls
    camera: Camera  # at the final size; presets scale it
    passes: tuple[str, ...] = ("draft", "preview")
    frame: int | None = None  # a training frame's codes (timeline), or the mean code
    inspect: bool = False  # also the colour variants behind the shadow and shading buffers
    buffers: tuple[str, ...] | None = None  # the avatar's optional buffers to make (render_image's; None: all)
    live: bool = False  # a live pose: one pass (live_pass), the next pose follows at once
    room: str | None = None  # a capture frame's own room (its file: the capture's camera moved), behind the render


@dataclass
class Result:
    request_id: int
    pass_name: str
    buffers: dict[str, np.ndarray]
    ms: float
    arrived: float = 0.0
    """When the window's side had it (time.perf_counter)."""


@dataclass
class PresetFigures:
    """A quality preset measured on the loaded avatar: time per frame and error against `final`."""

    ms: dict[str, float] = field(default_factory=dict)
    psnr_vs_final: dict[str, float] = field(default_factory=dict)
    size_px: int = 0
    """The image size they were measured at: the avatar's capture's (at most 256 px), else 128."""
    march: str = ""
    """What rendered them, where the model has more than one way (Avatar.describe_display: a primitives avatar's
    march, "C" or torch and why); "" for the others."""


FIRST_PIXELS_MS = 150.0
"""A slider move should show its first pixels within this."""
DELIVERY_MS = 50.0
"""Of a pass's latency, what is not its render: the pixels' way to the window and the window's frame that draws and
presents them (the demo's final at 256 px with the C march, median of 6 moves, three runs: 37-42 ms at 1280x800,
34-59 at 1920x1080 on llvmpipe, where a frame alone takes about 34 ms)."""
PASS_BUDGET_MS = FIRST_PIXELS_MS - DELIVERY_MS
"""A coarse pass is left out when a finer pass of the request, as lately timed at this size, renders within this
(100 ms; the demo primitives avatar's final at 256 px in the window took 57-76 ms, the medians of 6 moves in six
windows of three runs)."""
CORES = os.cpu_count() or 1
"""Cores a render may spread one batch over (RenderOptions.cores): the renderer keeps torch to one thread and gives
the primitives' march groups the machine's cores."""


TIMES_KEPT = 3
"""passes_to_render goes by the median of a pass's last this many render times: one slow frame (the window busy
at that moment) does not bring the coarse passes back (on the demo at 256 px in the C march, the final's own
render took 79 ms median and up to 94 in the window: by the last time alone, a third of the moves rendered the
preview first and put the final on screen 175 ms after the move)."""


def recent_ms(timed: dict[tuple[str, int], list[float]]) -> dict[tuple[str, int], float]:
    """The median of each pass's kept render times.

    >>> recent_ms({("final", 256): [79.0, 94.0, 81.0], ("preview", 256): [45.0]})
    {('final', 256): 81.0, ('preview', 256): 45.0}
    """
    return {k: float(np.median(v)) for k, v in timed.items() if v}


def passes_to_render(passes: tuple[str, ...], timed: dict[tuple[str, int], float], size: int) -> tuple[str, ...]:
    """The request's passes less those a finer pass within PASS_BUDGET_MS makes pointless; `timed`: the recent
    render time (ms) of each (pass, final size): the median of its last TIMES_KEPT (`recent_ms`).

    >>> passes_to_render(("draft", "preview", "final"), {("final", 128): 80.0, ("preview", 128): 50.0}, 128)
    ('final',)
    >>> passes_to_render(("draft", "preview", "final"), {("final", 256): 200.0, ("preview", 256): 85.0}, 256)
    ('preview', 'final')
    >>> passes_to_render(("draft", "preview", "final"), {("final", 256): 250.0, ("preview", 256): 112.0}, 256)
    ('draft', 'preview', 'final')
    """
    return tuple(name for i, name in enumerate(passes)
                 if not any(timed.get((later, size), np.inf) <= PASS_BUDGET_MS for later in passes[i + 1:]))


LIVE_PASS_MS = 70.0
"""A live pose renders one pass: the finest whose recent render time at this size is within this (live driving's
10 frames a second leave 100 ms a frame, of which the window's frame that shows it takes about 30), else the
coarsest."""


LIVE_PROBE_EVERY = 30
"""One live pose in this many renders the pass finer than live_pass chooses, so that a pass timed as too slow while
the machine was busy is timed again (its last times would otherwise keep it out for good)."""


def live_pass(passes: tuple[str, ...], timed: dict[tuple[str, int], float], size: int,
              probe: bool = False) -> tuple[str, ...]:
    """The one pass a live pose renders (`timed` as passes_to_render takes it; a pass not timed yet counts as fast
    enough: the presets' measurement at opening times them); with `probe`, the next finer one.

    >>> live_pass(("draft", "preview", "final"), {("final", 256): 62.0, ("preview", 256): 30.0}, 256)
    ('final',)
    >>> live_pass(("draft", "preview", "final"), {("final", 256): 210.0, ("preview", 256): 65.0}, 256)
    ('preview',)
    >>> live_pass(("draft", "preview", "final"), {("final", 256): 900.0, ("preview", 256): 300.0,
    ...                                           ("draft", 256): 90.0}, 256)
    ('draft',)
    >>> live_pass(("draft", "preview", "final"), {("final", 256): 210.0, ("preview", 256): 65.0}, 256, probe=True)
    ('final',)
    """
    fitting = [i for i, name in enumerate(passes) if timed.get((name, size), 0.0) <= LIVE_PASS_MS]
    chosen = fitting[-1] if fitting else 0
    return (passes[min(chosen + probe, len(passes) - 1)],)


def scaled(camera: Camera, scale: float) -> Camera:
    return camera.resized(max(8, round(camera.width_px * scale)), max(8, round(camera.height_px * scale)))


class NeuralWorker:
    """The window's side of the renderer process: requests go out, pixels come back (read by a thread that sets
    `result` and wakes the window's frame pacing through `arrived`)."""

    def __init__(self):
        ctx = mp.get_context("spawn")  # a fresh interpreter: no copy of the window's GL or threads
        self._latest = ctx.Value("q", 0, lock=False)
        """The newest request's id, in shared memory: the renderer's passes stop between batches once it moves."""
        inbox, self._requests = ctx.Pipe(duplex=False)
        """Requests go down a pipe, written by the window's thread as it submits them: through a Queue, its feeder
        thread waited for the interpreter lock while the window's thread drew (at 1920x1080 a request reached the
        renderer 10-30 ms after the move)."""
        self._results = ctx.Queue()
        self._id = 0
        self._avatar_id = 0
        self.result: Result | None = None
        self.arrived = threading.Event()
        """Set when a pass's pixels are stored: the window's frame pacing wakes on it, so they show at once."""
        self.busy = False
        self.due: float | None = None
        """When (time.perf_counter) the pass in flight should end, by its recent render times; None: not known."""
        self.error = ""
        self.figures = PresetFigures()
        self._proc = ctx.Process(target=serve, args=(inbox, self._results, self._latest),
                                 name="neural-render", daemon=True)
        self._proc.start()
        self._reader = threading.Thread(target=self._read, name="neural-results", daemon=True)
        self._reader.start()

    # ---- the window's side -----------------------------------------------------------------------------
    def _next_id(self) -> int:
        self._id += 1
        self._latest.value = self._id
        return self._id

    def set_avatar(self, folder: Path | None, measure: bool = True) -> None:
        """Render the avatar in this folder from now on (None: nothing); measure its presets when the controls
        rest."""
        self._avatar_id = self._next_id()
        self.result = None
        self.figures = PresetFigures()
        self._send(("avatar", self._avatar_id, None if folder is None else str(folder), measure))

    def submit(self, request: Request) -> int:
        rid = self._next_id()
        self.busy = True
        self.due = None
        self._send(("render", rid, request))
        return rid

    def _send(self, msg: tuple) -> None:
        with contextlib.suppress(OSError, ValueError):  # the renderer is gone: its error is shown
            self._requests.send(msg)

    def close(self) -> None:
        self._next_id()
        self._send(("quit",))
        self._proc.join(timeout=10)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(timeout=5)

    def _read(self) -> None:
        while True:
            try:
                msg = self._results.get()
            except (EOFError, OSError, ValueError):
                return
            kind = msg[0]
            if kind == "started":
                _, rid, ms = msg
                if rid == self._id:
                    self.due = None if ms is None else time.perf_counter() + ms / 1e3
            elif kind == "result":
                _, rid, name, buffers, ms = msg
                if rid == self._id:  # a pass of the newest request
                    self.due = None
                    self.result = Result(rid, name, buffers, ms, time.perf_counter())
                    self.error = ""
                    self.arrived.set()
            elif kind == "idle":
                if msg[1] == self._id:
                    self.busy, self.due = False, None
            elif kind == "figures":
                if msg[1] == self._avatar_id:
                    self.figures = msg[2]
            elif kind == "error":
                self.error = msg[1]
                self.busy, self.due = False, None
                self.arrived.set()
            elif kind == "closed":
                return


# ---- the renderer process ----------------------------------------------------------------------------------
def serve(pipe, results, latest) -> None:
    """The renderer's loop: the newest render request first, then (controls at rest) the presets' measurement;
    anything newer stops either between batches of rays. A thread empties the pipe of requests as they come, so
    that the window never waits on a full pipe while a pass renders."""
    import torch

    from models.avatars.base import RenderCancelled
    from models.avatars.registry import load_avatar
    from render.gl.context import GLContext
    from render.gl.raster import Rasterizer

    # At the window's own priority: the window's frames are held to a share of a core while it renders
    # (StudioConfig.rendering_window_share). Niced to 10, it lost the cores to the window's frame after each move
    # (the guide drawn anew): at 1920x1080 a pass began 30-40 ms after the request came.
    torch.set_num_threads(1)
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    avatar, avatar_id, measure = None, 0, False
    timed: dict[tuple[str, int], list[float]] = {}  # the loaded avatar's passes' last render times (recent_ms)
    stale = lambda rid: latest.value != rid
    taken = 0
    """The newest request id this loop has taken: a request the window has sent (`latest` moved) but the loop has
    not yet taken stops the presets' measurement too (timed from `latest` as it began, a measurement that began
    between the two ran to its end, 0.4 s, while the request waited)."""
    requests: queue.Queue = queue.Queue()
    live_renders = 0

    def take() -> None:
        while True:
            try:
                msg = pipe.recv()
            except (EOFError, OSError):  # the window is gone
                msg = ("quit",)
            requests.put(msg)
            if msg[0] == "quit":
                return

    threading.Thread(target=take, name="requests", daemon=True).start()
    try:
        while True:
            msgs = [requests.get()] if not measure or stale(taken) else []
            with contextlib.suppress(queue.Empty):
                while True:
                    msgs.append(requests.get_nowait())
            render = None
            for msg in msgs:
                if msg[0] == "quit":
                    return
                if msg[0] == "avatar":
                    _, avatar_id, folder, measure = msg
                    taken = avatar_id
                    render, timed = None, {}
                    try:
                        avatar = None if folder is None else load_avatar(folder)[0]
                        if avatar is not None:
                            warm_up(avatar, raster)
                    except Exception as e:  # the window read the same folder: this is rare
                        avatar, measure = None, False
                        results.put(("error", f"render failed: {type(e).__name__}: {e}"))
                elif msg[0] == "render":
                    render, taken = msg, msg[1]
            if avatar is None:
                measure = False
                if render is not None:
                    results.put(("idle", render[1]))
                continue
            try:
                if render is not None:
                    _, rid, request = render
                    live_renders += request.live
                    render_passes(avatar, raster, request, rid, stale, results, timed,
                                  probe=request.live and live_renders % LIVE_PROBE_EVERY == 0)
                    results.put(("idle", rid))
                elif measure:
                    figures = measure_presets(avatar, raster, lambda since=taken: stale(since))
                    results.put(("figures", avatar_id, figures))
                    seed_times(timed, figures)
                    measure = False
            except RenderCancelled:
                if render is not None:
                    results.put(("idle", render[1]))
            except Exception as e:  # shown in the window; the studio keeps running
                results.put(("error", f"render failed: {type(e).__name__}: {e}"))
    except (EOFError, OSError, KeyboardInterrupt):  # the window is gone
        return
    finally:
        raster.release()
        gl.release()
        with contextlib.suppress(OSError, ValueError):
            results.put(("closed",))


def render_passes(avatar, raster, request: Request, rid: int, stale, results,
                  timed: dict[tuple[str, int], list[float]], probe: bool = False) -> None:
    """Each pass of the request worth rendering (passes_to_render), coarse to fine, its pixels sent as soon as they
    are made; each pass's time goes into `timed` (its last TIMES_KEPT kept)."""
    size = request.camera.width_px
    recent = recent_ms(timed)
    passes = live_pass(request.passes, recent, size, probe) if request.live else \
        passes_to_render(request.passes, recent, size)
    qualities = [avatar.card.presets[name].quality for name in passes]
    for i, name in enumerate(passes):
        if i + 1 < len(qualities) and qualities[i + 1] == qualities[i]:
            continue  # the bench may choose one setting for two presets: render it once, as the finer
        cam = scaled(request.camera, qualities[i].scale)
        results.put(("started", rid, recent.get((name, size))))  # the window paces its frames by it
        t0 = time.perf_counter()
        options = RenderOptions(frame=request.frame, inspect=request.inspect, buffers=request.buffers,
                                chunk_rays=avatar.interactive_chunk_rays, should_stop=lambda: stale(rid), cores=CORES,
                                quality=qualities[i], room=None if request.room is None else room_image(request.room))
        buffers = render_image(avatar, cam, request.controls, options, raster)
        ms = 1e3 * (time.perf_counter() - t0)
        if stale(rid):
            return
        timed[name, size] = [*timed.get((name, size), [])[1 - TIMES_KEPT:], ms]
        results.put(("result", rid, name, buffers, ms))


@functools.lru_cache(maxsize=2)
def room_image(path: str) -> np.ndarray:
    """(H,W,3) a capture frame's room, read once while its frame is shown (each of its passes renders it)."""
    return read_room(path)


def warm_up(avatar, raster) -> None:
    """One 32 px render of a newly loaded avatar, so that its first pass is timed as the later ones are: on the
    demo at 256 px the first final took 95 ms and the next ones 75-81 (one thread, alone), and with no other time
    yet the window's first slider move went by that one (the preview first, the final on screen 178 ms after
    the move); after this 56 ms render the first final takes 73."""
    cam = framing_camera(avatar.card.rest_vertices(), 25, 5, fov_y_deg=18.0, width_px=32, height_px=32)
    options = RenderOptions(buffers=None, cores=CORES, quality=avatar.card.presets["draft"].quality)
    render_image(avatar, cam, avatar.card.at_rest(Controls()), options, raster)


def seed_times(timed: dict[tuple[str, int], list[float]], figures: PresetFigures) -> None:
    """The presets' times measured at rest (`measure_presets`, the median of 3 renders each) for the passes of
    that size not yet timed by a request: a move after the avatar opened chooses its passes by them.

    >>> timed = {("final", 256): [80.0]}
    >>> seed_times(timed, PresetFigures(ms={"final": 70.0, "draft": 20.0}, size_px=256))
    >>> timed
    {('final', 256): [80.0], ('draft', 256): [20.0]}
    """
    for name, ms in figures.ms.items():
        timed.setdefault((name, figures.size_px), [ms])


def measure_presets(avatar, raster, should_stop) -> PresetFigures:
    """Each preset's median time over 3 renders of a 3/4 view and its PSNR against `final`, at the size of
    the avatar's capture (a tracked video's 256 px costs four times a synthetic capture's 128): the colour render
    the studio shows first (no optional buffers: render_image's buffers=())."""
    from models.training.metrics import psnr

    size = min(avatar.card.capture_px or 128, 256)
    cam = framing_camera(avatar.card.rest_vertices(), 25, 5, fov_y_deg=18.0, width_px=size, height_px=size)
    figures = PresetFigures(size_px=size)
    images = {}
    for name in ("final", "preview", "draft"):
        quality = avatar.card.presets[name].quality
        c = scaled(cam, quality.scale)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            options = RenderOptions(buffers=(), chunk_rays=avatar.interactive_chunk_rays, should_stop=should_stop,
                                    cores=CORES, quality=quality)
            images[name] = render_image(avatar, c, avatar.card.at_rest(Controls()), options, raster)["rgb"]
            times.append(1e3 * (time.perf_counter() - t0))
        figures.ms[name] = float(np.median(times))
        reference = images["final"]
        if images[name].shape != reference.shape:  # compare at the final size (nearest upsampling, any ratio:
            (h, w), (H, W) = images[name].shape[:2], reference.shape[:2]  # a preview at 3/4 of 256 px is 192)
            images[name] = images[name][np.arange(H) * h // H][:, np.arange(W) * w // W]
        figures.psnr_vs_final[name] = float("inf") if name == "final" else psnr(images[name], reference)
    figures.march = avatar.describe_display()
    return figures
