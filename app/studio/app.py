"""The studio window (docs/studio.md): glfw + Dear ImGui (imgui-bundle) + moderngl, on the CPU. The window's thread
only draws; the neural render, exports and training run elsewhere (a thread, a thread, processes), so
the interface keeps its frame rate.

Scripted runs (tests, README pictures): --screenshot PNG --frames N saves the whole window after N frames and
exits; --script JSON runs a list of steps (set sliders, open avatars, train, export, wait, save pictures)."""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
from imgui_bundle import hello_imgui, imgui, immapp
from PIL import Image

from app.animation import AnimationError
from app.display import render_needs
from app.errors import INPUT_ERRORS, UserInputError
from app.jobs import JobQueue
from app.sliders import sliders_json
from app.studio import actions as a
from app.studio import avatar_panel, controls_panel, export_panel, jobs_panel, live_panel, quality_panel, viewport
from app.studio.config import LiveConfig, StudioConfig
from app.studio.context import PanelContext
from app.studio.display import display_problem
from app.studio.exporting import Exporter
from app.studio.live import LiveFigures, LiveWorker, source_problem
from app.studio.neural import NeuralWorker, Request
from app.studio.script import Script
from app.studio.script_fields import ScriptError
from app.studio.session import AvatarFiles, Session, read_avatar_folder, remember_recent
from app.user_config import find_landmarker
from render.gl.context import GLContext

REPO = Path(__file__).resolve().parents[2]
DEMO_AVATAR = REPO / "resources" / "demo_avatar"


class FrameClock:
    """Interface frame rates, kept apart for idle, rendering, training, loading and playing an animation."""

    def __init__(self):
        self.last = time.perf_counter()
        states = ("idle", "rendering", "training", "loading", "playing")
        self.times: dict[str, deque] = {k: deque(maxlen=240) for k in states}
        """Frame times by what the studio was doing ("loading": while an avatar is read in the background)."""
        self.started = False
        self.recent: deque = deque(maxlen=60)

    def tick(self, state: str) -> float:
        now = time.perf_counter()
        dt, self.last = now - self.last, now
        if not self.started:  # the first frame holds the window's creation: no interface rate
            self.started = True
            return dt
        self.times[state].append(dt)
        self.recent.append(dt)
        return dt

    def fps(self, state: str | None = None) -> float:
        t = self.recent if state is None else self.times[state]
        return len(t) / sum(t) if t and sum(t) > 0 else 0.0


@dataclass
class Opening:
    """An avatar folder being read in the background."""

    folder: Path
    thread: threading.Thread | None = None
    files: AvatarFiles | None = None
    error: str | None = None
    seconds: float = 0.0


class Studio:
    """The application: the Session (one value), the workers that serve it (the neural render, training jobs,
    exports, avatar reading), the panels that draw it, and the actions that change it."""

    def __init__(self, cfg: StudioConfig, live: str | None = None):
        self.cfg = cfg
        self.script = Script.load(cfg.script) if cfg.script else None
        """Read and checked first: a wrong script ends the command before a renderer starts or a window opens."""
        self.session = Session()
        self.opening: Opening | None = None
        self.loading_s: list[float] = []
        """Seconds each avatar took to read (off the window's thread)."""
        self.worker = NeuralWorker()
        self.jobs = JobQueue()
        self.exporter = Exporter()
        self.gui_ms: deque = deque(maxlen=240)
        """Time the window's own Python code takes a frame (the rest of a frame is drawing and presenting)."""
        self.frame_cpu_ms: deque = deque(maxlen=240)
        """The window process's CPU time of each recent frame, its GL driver's drawing threads included (FrameCpu)."""
        self.last_submit_id = 0
        self.last_submit_time = 0.0
        self.latency_ms: float | None = None
        self.latency_from = "slider"
        """What latency_ms is counted from: a change ("slider"), or an avatar's opening (no pixels of it yet: the
        renderer reads it first, seconds on a first launch, which the header must not pass off as a slider's)."""
        self.pass_latency_ms: dict[str, float] = {}
        """Since the last request: ms from its submission to each of its passes' pixels on screen (draft, preview,
        final): stamped when the frame that draws them has been presented (`presented`)."""
        self.pass_render_ms: dict[str, float] = {}
        """Each pass's own render time (of those latencies, what the renderer took)."""
        self.drawn: list[str] = []
        """Passes of the last request drawn in this frame, not yet presented."""
        self.clock = FrameClock()
        self.frame_count = 0
        self.gl: GLContext | None = None
        self.viewport = viewport.Viewport()
        self.confirm_close = False
        self.keep_jobs = False
        """The user chose to keep training after the window closes (otherwise closing stops the jobs)."""
        self.last_play_tick: float | None = None
        self.pending_viewport_shot: Path | None = None
        self.after_open: Path | None = None
        """An animation to put on the timeline once the avatar being opened is open (a reenactment's)."""
        self.live: LiveWorker | None = None
        """Live driving's tracker (app/studio/live.py), while a source drives the avatar."""
        self.live_applied = 0
        """The live poses taken so far (LiveWorker.received when last looked)."""
        self.live_after_open: str | None = live
        """A live source to start once the first avatar is open (the `live` command's)."""
        self.live_figures = LiveFigures()

    # ---- actions -----------------------------------------------------------------------------------------
    def act(self, action: a.Action | a.Command) -> None:
        """Apply an action to the Session, or carry out a command."""
        if isinstance(action, a.Action):
            action.apply(self.session)
            return
        match action:
            case a.OpenAvatar(folder):
                self.open_avatar(folder)
            case a.StartTraining():
                self.session.job_message = jobs_panel.start(self.jobs, action) or ""
            case a.StartFromVideo():
                self.session.job_message = jobs_panel.start_from_video(self.jobs, action) or ""
            case a.StartReenact():
                self.session.job_message = jobs_panel.start_reenact(self.jobs, self.session.folder, action) or ""
            case a.OpenReenactment(job_id):
                for job in self.jobs.jobs:
                    if job.id == job_id:
                        self.open_reenactment(job.dataset, job.out.with_suffix(".json"))
            case a.CancelJob(job_id):
                for job in self.jobs.jobs:
                    if job_id is None or job.id == job_id:
                        self.jobs.cancel(job)
            case a.ResumeJob(job_id):
                for job in self.jobs.jobs:
                    if job.id == job_id:
                        self.jobs.resume(job)
            case a.ExportTurntable(cfg):
                if cfg.out.suffix.lower() != ".mp4":
                    self.session.report(f"{cfg.out}: the turntable is written as an .mp4")
                else:
                    self.exporter.start(cfg, self.session.controls())
            case a.ExportAnimation(out, size, preset):
                s = self.session
                if out.suffix.lower() != ".mp4":
                    s.report(f"{out}: the animation is written as an .mp4")
                elif s.folder is None or not s.animation.tracks:
                    s.report("nothing to export: key a pose first")
                else:
                    self.exporter.start_animation(s.folder, s.animation, out, max(16, size - size % 2), preset)
            case a.CancelExport():
                self.exporter.cancel()
            case a.SaveViewport(path):
                self.save_viewport(path)
            case a.StartLive(source):
                self.start_live(source)
            case a.StopLive():
                self.stop_live("")
            case a.LiveNeutral():
                if self.live is not None:
                    self.live.set_neutral()
            case _:
                raise TypeError(f"no such studio command: {action!r}")

    def open_avatar(self, folder: str | Path) -> None:
        """Start reading an avatar folder on a thread of its own; the window goes on drawing (with the open
        avatar, if any) and the new one takes its place when read (poll_opening). A later request wins."""
        opening = Opening(Path(folder))

        def read() -> None:
            t0 = time.perf_counter()
            try:
                opening.files = read_avatar_folder(opening.folder)
            except INPUT_ERRORS as e:
                opening.error = str(e)
            except Exception as e:  # a broken file is the file's problem, never the studio's end
                opening.error = f"{folder}: could not open ({type(e).__name__}: {e})"
            opening.seconds = time.perf_counter() - t0

        opening.thread = threading.Thread(target=read, name="open-avatar", daemon=True)
        opening.thread.start()
        self.opening = opening
        self.session.opening = opening.folder

    def open_reenactment(self, avatar: Path, animation: Path) -> None:
        """A reenactment's animation on the timeline, once its avatar is open."""
        folder = self.session.folder
        if folder is not None and Path(folder).resolve() == Path(avatar).resolve() and self.opening is None:
            self.act(a.LoadAnimation(animation))
        else:
            self.open_avatar(avatar)
            self.after_open = animation

    def poll_opening(self) -> None:
        o = self.opening
        if o is None or o.thread.is_alive():
            return
        self.opening = None
        self.loading_s.append(o.seconds)
        after, self.after_open = self.after_open, None
        if o.error is not None:
            self.act(a.OpenFailed(o.error))
            return
        self.act(a.AvatarOpened(o.files))
        remember_recent(o.folder)
        self.worker.set_avatar(o.files.folder)
        if self.live is not None:  # the source goes on driving the avatar now open, in its head model's terms
            self.start_live(self.live.source)
        if after is not None:
            self.act(a.LoadAnimation(after))

    def start_live(self, source: str) -> None:
        """Track the source in a process of its own and drive the open avatar by it (poll_live)."""
        s = self.session
        if s.avatar is None:
            s.report("live driving needs an open avatar")
            return
        try:
            bundle = find_landmarker()
        except INPUT_ERRORS as e:
            s.report(str(e))
            return
        self.stop_live("")
        self.live = LiveWorker(source.strip(), bundle, s.avatar.head_model, self.wake_for_pose)
        self.live_applied = 0
        self.live_figures = LiveFigures()
        self.act(a.LiveStarted(source.strip()))

    def wake_for_pose(self) -> None:
        """A live pose came (on the live worker's thread): the window's wait ends where the renderer can take it."""
        if not self.worker.busy or self.live is None or self.live.state != "running":
            self.worker.arrived.set()

    def stop_live(self, message: str, wait: bool = False) -> None:
        if self.live is not None:
            self.live.close(wait)
            self.live = None
        if self.session.live.running:
            self.act(a.LiveStopped(message))

    def poll_live(self) -> None:
        """The newest tracked pose onto the sliders (older ones not yet taken are passed over); the end of the
        source, or its failure, stops live driving with its reason."""
        live = self.live
        if live is None:
            return
        live.check()
        if live.received > self.live_applied and live.pose is not None:
            pose = live.pose
            self.live_applied = live.received
            self.live_figures.took(pose)
            try:
                self.act(a.LivePose(pose.channels, pose.stamp, pose.index))
            except AnimationError as e:  # a channel the open avatar has not: said once, and live driving stops
                self.stop_live(f"live: {e}")
                return
        if live.state in ("ended", "failed"):
            message = live.message if live.state == "failed" else f"live: {live.source}: {live.message}"
            self.stop_live(message)

    def render_due(self) -> bool:
        """Whether a new request may go to the renderer now. While live, not before the request in flight has shown
        its first pixels: each pose in turn would cancel the one before it, and none would be shown. The newest pose
        waits on the sliders meanwhile, and older ones are dropped."""
        if not self.session.live.running or not self.worker.busy:
            return True
        r = self.worker.result
        return r is not None and r.request_id == self.last_submit_id

    def save_viewport(self, path: Path) -> None:
        """The viewport as shown (the guide and the render, beside or over each other), as a PNG: read from the
        window once this frame is drawn (take_viewport_shot)."""
        if self.viewport.rect is None:
            self.session.report("nothing shown yet to save")
            return
        self.pending_viewport_shot = path

    def take_viewport_shot(self) -> None:
        """Called with the frame drawn: save the pending viewport screenshot."""
        path, self.pending_viewport_shot = self.pending_viewport_shot, None
        if path is None or self.viewport.rect is None:
            return
        x, y, w, h = self.viewport.rect
        img = self.read_window()[max(y, 0):y + h, max(x, 0):x + w]
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(np.ascontiguousarray(img)).save(path)
        except (OSError, ValueError) as e:
            self.session.report(f"{path}: cannot save the screenshot ({e})")
            return
        self.exporter.message = f"saved {path}"

    # ---- per frame ---------------------------------------------------------------------------------------
    def submit_if_due(self) -> None:
        """A new render request where the Session changed and the renderer may take one (render_due)."""
        if self.session.dirty and self.render_due():
            self.latency_ms = None
            self.pass_latency_ms = {}
            self.pass_render_ms = {}
            self.drawn = []
            self.submit_render()

    def submit_render(self) -> None:
        s = self.session
        if s.avatar is None:
            return
        cam = s.render_camera(s.display.neural_size)
        passes = ("draft", "preview", "final")[: ("draft", "preview", "final").index(s.display.refine_to) + 1]
        frame = s.timeline_frame if s.timeline_frame >= 0 else None
        buffers, inspect = render_needs(s.display.buffer)
        live = s.live.stamp is not None
        if live and s.display.live_pass != "auto":
            passes = (s.display.live_pass,)
        self.last_submit_id = self.worker.submit(Request(s.controls(), cam, passes, frame, inspect=inspect,
                                                         buffers=buffers, live=live, room=s.render_room()))
        self.last_submit_time = time.perf_counter()
        self.live_figures.submitted(self.last_submit_id, s.live.index, s.live.stamp)
        if live and self.live is not None:  # the next pose, tracked to be ready when this render should be done
            self.live.want(self.last_submit_time + self.live_figures.render_s())
        s.live.stamp = None
        self.latency_from = "slider" if self.worker.result is not None else "opening"
        s.dirty = False

    def may_idle(self) -> bool:
        """Whether the window may drop to cfg.idle_fps until the user acts: nothing it shows moves on its own (no
        render in flight or due, no live performer, no animation playing, nothing opening). A job's or an export's
        progress is shown at the idle rate, and the cores go to them. A script idles only while it waits for a job
        or an export; a --screenshot run never does."""
        s = self.session
        if self.worker.busy or s.dirty or s.live.running or s.playing or self.opening is not None or \
                self.pending_viewport_shot is not None or self.cfg.screenshot:
            return False
        return self.script is None or self.script.may_idle

    def context(self) -> PanelContext:
        return PanelContext(self.session, self.act, self.worker, self.jobs, self.exporter, self.clock.fps(),
                            float(np.median(self.gui_ms)) if self.gui_ms else None, self.latency_ms,
                            self.latency_from, self.live_figures if self.live is not None else None)

    def gui(self) -> None:
        t0 = time.perf_counter()
        self._gui()
        self.gui_ms.append(1e3 * (time.perf_counter() - t0))

    def _gui(self) -> None:
        if self.gl is None:
            self.gl = GLContext.from_current_window()
            self.viewport.init(self.gl)
            if self.cfg.avatar is not None or DEMO_AVATAR.is_dir():
                self.open_avatar(self.cfg.avatar or DEMO_AVATAR)
        self.poll_opening()
        if self.live_after_open is not None and self.session.avatar is not None:
            source, self.live_after_open = self.live_after_open, None
            self.start_live(source)
        self.poll_live()
        self.jobs.poll()
        for job in self.jobs.jobs:  # a new avatar from video opens when its job is done, a reenactment too
            if job.video is not None and job.state == "done" and not job.opened:
                job.opened = True
                if job.stage == "reenact":
                    self.open_reenactment(job.dataset, job.out.with_suffix(".json"))
                else:
                    self.open_avatar(job.out)
        if self.session.playing:  # the animation's time follows the clock, round and round
            now = time.perf_counter()
            dt, self.last_play_tick = now - (self.last_play_tick or now), now
            s = self.session
            self.act(a.SeekAnimation((s.anim_time + dt) % max(s.animation.duration_s, 1e-3)))
        else:
            self.last_play_tick = None
        state = "training" if self.jobs.running() else "loading" if self.opening else \
            "playing" if self.session.playing else "rendering" if self.worker.busy else "idle"
        self.clock.tick(state)
        if self.script is not None:
            self.script.step(self)
            if self.script.over:
                hello_imgui.get_runner_params().app_shall_exit = True
        result = self.worker.result
        if result is not None and result.request_id == self.last_submit_id and \
                result.pass_name not in self.pass_render_ms:
            self.pass_render_ms[result.pass_name] = result.ms
            self.drawn.append(result.pass_name)
            self.live_figures.drawing(result.request_id, result.ms, result.pass_name, result.arrived)
        if self.session.live.stamp is not None:
            self.submit_if_due()  # a live pose goes to the renderer before this frame is drawn, not after

        w, h = imgui.get_io().display_size
        left, right = 330, 420
        ctx = self.context()
        self._window("Avatar", (0, 0), (left, 260), lambda: avatar_panel.draw(ctx))
        self._window("Controls", (0, 260), (left, h - 260), lambda: (live_panel.draw(ctx), controls_panel.draw(ctx)))
        self._window("Viewport", (left, 0), (w - left - right, h), lambda: viewport.draw(ctx, self.viewport))
        self._window("Quality", (w - right, 0), (right, 200), lambda: quality_panel.draw(ctx))
        self._window("Jobs", (w - right, 200), (right, h - 440), lambda: jobs_panel.draw(ctx))
        self._window("Export", (w - right, h - 240), (right, 240), lambda: export_panel.draw(ctx))
        self._close_dialog()
        self.submit_if_due()
        self.frame_count += 1
        if self.cfg.screenshot and self.script is None and self.frame_count >= self.cfg.frames:
            hello_imgui.get_runner_params().app_shall_exit = True

    def _window(self, title: str, pos, size, body, extra_flags: int = 0) -> None:
        imgui.set_next_window_pos(imgui.ImVec2(*pos), imgui.Cond_.always)
        imgui.set_next_window_size(imgui.ImVec2(*size), imgui.Cond_.always)
        flags = imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
        # The panels tile the window, whose clear colour is the panels' background: filling each panel's background
        # again would cost a whole window's worth of software GL every frame (~8 ms at 1440x900 on llvmpipe).
        flags |= extra_flags | imgui.WindowFlags_.no_background
        if imgui.begin(title, None, flags)[0]:
            try:
                body()
            except Exception as e:  # a panel's bug shows as a message, the window goes on
                self.session.report(f"{title}: {type(e).__name__}: {e}")
        imgui.end()

    def _close_dialog(self) -> None:
        if self.confirm_close:
            imgui.open_popup("Training is running")
            self.confirm_close = False
        if imgui.begin_popup_modal("Training is running", None, imgui.WindowFlags_.always_auto_resize)[0]:
            imgui.text(f"{len(self.jobs.running())} training job(s) running.")
            if imgui.button("Keep training in the background"):
                self._exit(keep_jobs=True)
            imgui.same_line()
            if imgui.button("Stop them (checkpointed)"):
                self._exit(keep_jobs=False)
            imgui.same_line()
            if imgui.button("Cancel"):
                imgui.close_current_popup()
            imgui.end_popup()

    def confirm_exit(self) -> bool:
        """The window's close button: ask first when training runs."""
        if self.jobs.running():
            self.confirm_close = True
            return False
        return True

    def _exit(self, keep_jobs: bool) -> None:
        self.keep_jobs = keep_jobs
        hello_imgui.get_runner_params().app_shall_exit = True

    def read_window(self) -> np.ndarray:
        """The window's pixels (H,W,3) uint8, top row first (the frame just drawn)."""
        with self.gl.current():
            fb = self.gl.ctx.detect_framebuffer(0)
            w, h = fb.size
            data = fb.read(components=3, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(h, w, 3)[::-1].copy()

    def presented(self) -> None:
        """After the swap: the passes this frame drew are on screen now (their latencies)."""
        ms = 1e3 * (time.perf_counter() - self.last_submit_time)
        for name in self.drawn:
            self.latency_ms = ms if self.latency_ms is None else self.latency_ms
            self.pass_latency_ms.setdefault(name, ms)
        self.live_figures.shown(time.perf_counter())
        self.drawn = []

    def figures(self) -> dict:
        """Measured figures for reports: interface fps per state, latency, the last pass's time."""
        r = self.worker.result
        return {"fps_idle": round(self.clock.fps("idle"), 1), "fps_rendering": round(self.clock.fps("rendering"), 1),
                "fps_training": round(self.clock.fps("training"), 1),
                "fps_playing": round(self.clock.fps("playing"), 1),
                "animation": self.session.animation.to_json(), "anim_time": round(self.session.anim_time, 3),
                "sliders": sliders_json(self.session.sliders), "poses": sorted(self.session.poses),
                "frames": {k: len(v) for k, v in self.clock.times.items()},
                "loading_s": [round(x, 2) for x in self.loading_s],
                "fps_loading": round(self.clock.fps("loading"), 1),
                "gui_ms_median": round(float(np.median(self.gui_ms)), 2) if self.gui_ms else None,
                "frame_cpu_ms_median": round(float(np.median(self.frame_cpu_ms)), 2) if self.frame_cpu_ms else None,
                "latency_ms": None if self.latency_ms is None else round(self.latency_ms, 1),
                "pass_latency_ms": {k: round(v, 1) for k, v in self.pass_latency_ms.items()},
                "last_pass": None if r is None else {"pass": r.pass_name, "ms": round(r.ms, 1)},
                "presets": {"ms": self.worker.figures.ms, "psnr_vs_final": self.worker.figures.psnr_vs_final},
                "errors": list(self.session.errors),
                "viewport": {"space": self.viewport.space, "rect": self.viewport.rect,
                             "guide_draws": self.viewport.guide_draws,
                             "images": dict(self.viewport.images)},
                "live": {**self.live_figures.report(self.live), "render_px": self.session.display.neural_size},
                "steps_run": None if self.script is None else self.script.ran,
                "latencies": None if self.script is None else self.script.latencies,
                "sliders_log": None if self.script is None else self.script.sliders_log,
                "live_log": None if self.script is None else self.script.live_log}

    def close(self) -> None:
        """The window is gone, however it ended (closed, a script done or failed, an error): the renders stop,
        and so do the training jobs (checkpointed) unless the user chose to keep them."""
        self.stop_live("", wait=True)
        self.worker.close()
        self.exporter.cancel()
        if not self.keep_jobs:
            self.jobs.stop_all()


class FrameCpu:
    """The window process's CPU time per frame (its GL driver's threads included: on a software GL they draw),
    smoothed over the last frames."""

    def __init__(self) -> None:
        self.last = time.process_time()
        self.used = 0.0
        """The last frame's, unsmoothed."""
        self.seconds = 0.0

    def tick(self) -> float:
        now = time.process_time()
        self.used, self.last = now - self.last, now
        self.seconds = self.used if self.seconds == 0.0 else 0.8 * self.seconds + 0.2 * self.used
        return self.seconds


MAX_HOLD_S = 0.2
"""The longest frame_wait holds the window for pixels that are due (the window's input waits as long)."""


def frame_wait(now: float, last_end: float, cap_fps: float, due: float | None) -> float:
    """Seconds to wait before the next frame: what is left of 1/cap_fps since the last wait ended (`last_end`; the
    frame since then took now - last_end). Where a pass's pixels are `due` before a frame started after that would
    be presented, the window waits for them instead (their arrival ends the wait), until one frame's time after
    they are due and at most MAX_HOLD_S: a frame drawn just before they came would hold them back by most of a
    frame (at 1920x1080 on a software GL, 21-27 ms of a 34 ms frame).

    >>> round(frame_wait(1.010, 1.0, 60.0, None), 4)  # a 10 ms frame at 60 fps
    0.0067
    >>> round(frame_wait(1.034, 1.0, 20.0, 1.054), 4)  # pixels due in 20 ms: wait for them, up to 1.088
    0.054
    >>> round(frame_wait(1.034, 1.0, 20.0, 1.300), 4)  # due long after the next frame: the cap alone
    0.016
    >>> round(frame_wait(1.034, 1.0, 20.0, 1.0), 4)  # late: past their time and a frame's, the cap alone
    0.016
    """
    frame_s = now - last_end
    spare = 1.0 / cap_fps - frame_s
    if due is not None and now + max(spare, 0.0) + frame_s > due:
        spare = max(spare, min(due + frame_s, now + MAX_HOLD_S) - now)
    return spare


def run_live(cfg: LiveConfig) -> int:
    """The studio, driven live from the start by a camera or a video file; one line and exit status 2 where the
    source cannot be opened (no camera there, no such video)."""
    if cfg.avatar is not None and not (cfg.avatar / "avatar.json").is_file():
        raise UserInputError(f"{cfg.avatar}: not an avatar folder (no avatar.json)")
    problem = source_problem(cfg.source)
    if problem:
        raise UserInputError(problem)
    find_landmarker()  # none: one line, exit status 2, before a window opens
    return run_studio(StudioConfig(**{f.name: getattr(cfg, f.name) for f in fields(StudioConfig)}), live=cfg.source)


def run_studio(cfg: StudioConfig, live: str | None = None) -> int:
    problem = display_problem()
    if problem:
        raise UserInputError(problem)
    studio = Studio(cfg, live)
    params = hello_imgui.RunnerParams()
    params.app_window_params.window_title = "Avatar Studio"
    params.app_window_params.window_geometry.size = (cfg.width, cfg.height)
    params.callbacks.show_gui = studio.gui
    params.callbacks.confirm_exit = studio.confirm_exit
    # Idling (hello_imgui waits for input, up to 1 / idle_fps): allowed frame by frame (Studio.may_idle).
    params.fps_idling.fps_idle = cfg.idle_fps
    params.fps_idling.fps_idling_mode = hello_imgui.FpsIdlingMode.sleep
    params.fps_idling.enable_idling = False
    # No multisampling for the window (hello_imgui asks for 8 samples a pixel by default): ImGui anti-aliases its
    # own shapes and the guide is drawn in a framebuffer of its own, so the samples bought nothing, and on a software
    # GL (llvmpipe) they tripled a window frame's CPU (25 ms against 8.5 at 1280x800; the frame_cpu_ms figure).
    # Live, the whole head's pixels came 121 ms after the camera frame against 153 (docs/live.md).
    gl_options = hello_imgui.OpenGlOptions()
    gl_options.anti_aliasing_samples = 0
    params.renderer_backend_options.open_gl_options = gl_options
    # The panels tile the whole window: hello_imgui's own full-window background under them would be drawn
    # for nothing, and on a software GL (llvmpipe) filling the window once more costs ~12 ms a frame.
    params.imgui_window_params.default_imgui_window_type = hello_imgui.DefaultImGuiWindowType.no_default_window
    params.imgui_window_params.background_color = imgui.ImVec4(0.06, 0.06, 0.06, 1.0)  # the dark style's panels
    params.ini_disable = True
    shots: list = []
    last_swap = [time.perf_counter()]
    frame_cpu = FrameCpu()

    def before_swap() -> None:
        if cfg.screenshot and hello_imgui.get_runner_params().app_shall_exit and not shots:
            shots.append(studio.read_window())
        studio.take_viewport_shot()
        if studio.script is not None:
            studio.script.after_frame(studio)

    def after_swap() -> None:
        # The cap: no display sync here, so without it the interface would take a whole core. Counted from the
        # end of the previous frame's wait, so that only what is left of a whole frame's time is slept. Slept
        # after the swap, not before it: new pixels that end the wait go into the very next frame, where before
        # the swap they waited for the frame already drawn to be presented first (on a software GL the swap
        # rasterizes: at 1920x1080 that is most of a 34 ms frame).
        studio.presented()
        cpu_s = frame_cpu.tick()
        studio.frame_cpu_ms.append(1e3 * frame_cpu.used)
        cap = cfg.fps_cap
        worker = studio.worker
        if worker.busy:
            cap = min(cap, cfg.rendering_fps_cap, max(8.0, cfg.rendering_window_share / max(cpu_s, 1e-4)))
        spare = frame_wait(time.perf_counter(), last_swap[0], cap, worker.due if worker.busy else None)
        if spare > 0:  # a pass's new pixels end the wait: the next frame shows them
            worker.arrived.wait(spare)
        studio.worker.arrived.clear()
        last_swap[0] = time.perf_counter()
        hello_imgui.get_runner_params().fps_idling.enable_idling = studio.may_idle()

    params.callbacks.before_swap = before_swap
    params.callbacks.after_swap = after_swap

    def post_init() -> None:
        # A panel's mistake (an exception between a push and its pop) is recovered and logged, not fatal.
        io = imgui.get_io()
        io.config_error_recovery = True
        io.config_error_recovery_enable_assert = False

    params.callbacks.post_init = post_init
    try:
        addons = immapp.AddOnsParams()
        addons.with_implot = True
        immapp.run(params, addons)
    finally:
        studio.close()
    if cfg.screenshot:
        image = shots[0] if shots else hello_imgui.final_app_window_screenshot()
        cfg.screenshot.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(np.ascontiguousarray(image[..., :3])).save(cfg.screenshot)
        print(f"wrote {cfg.screenshot}")
    if studio.script is not None and studio.script.report:
        studio.script.report.write_text(json.dumps(studio.figures(), indent=1))
    if studio.script is not None and studio.script.failed:  # one line, exit status 2 (app/cli.py)
        raise ScriptError(f"{cfg.script}: {studio.script.failed}")
    return 0

