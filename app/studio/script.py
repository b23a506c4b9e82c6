"""Scripted studio runs: a JSON file {"report": PATH, "steps": [...]} whose steps act through the same code
the widgets call, one step per frame, with waits that keep the window drawing (tests under Xvfb, README
pictures). Every step is checked before the window opens (app/studio/script_fields.py: its action, the kind of
its value, the fields beside it); a step that cannot be done ends the run with one line naming it, steps[INDEX]
(ACTION), and the problem (the command exits 2). Steps:

  {"open": FOLDER}                        open an avatar (errors land in the window's messages)
  {"expression": NAME|INDEX, "value": W}  move an expression slider
  {"jaw_open_deg": D}                     open the jaw, degrees
  {"head": [YAW, PITCH, ROLL]}            turn the head, degrees
  {"gaze": [YAW, PITCH]}                  turn both eyes, degrees
  {"view": {"yaw_deg": ...}}              the orbit camera (yaw_deg, pitch_deg, zoom, fov_deg)
  {"buffer": NAME}                        the neural buffer on screen
  {"timeline": FRAME}                     show a capture frame's controls (-1: the sliders)
  {"refine_to": PRESET}                   the pass the viewport refines to
  {"wait_render": PRESET}                 until the latest request's pass PRESET (or a finer one) is on screen
  {"record_latency": true}                the ms from the last change to its first pixels ("first") and to each
                                          of its passes' pixels (passes a faster finer one made pointless are
                                          left out: app/studio/neural.py), and as "PASS render" each pass's own
                                          render time, kept for the report's
                                          "latencies" (benchmarks/bench_studio.py)
  {"undo": true}                          undo the last slider or camera change (Ctrl+Z)
  {"redo": true}                          redo it (Ctrl+Shift+Z)
  {"reset": GROUP}                        a group back to rest: expression[:brows|eyes|mouth|...], head, neck, jaw,
                                          gaze, camera
  {"record_sliders": true}               keep the sliders' values (and how often the guide was drawn) now, for
                                          the report's "sliders_log"
  {"save_pose": NAME}                     save the sliders as a named pose of this avatar
  {"recall_pose": NAME}                   set the sliders to a named pose
  {"key": true}                           key the pose at the animation's time (Animation tab's "Key pose")
  {"seek": SECONDS}                       move along the animation (its keyed channels set the sliders)
  {"play": BOOL}                          play or stop the animation
  {"save_animation": JSON}                save the animation's keys
  {"load_animation": JSON}                load an animation's keys
  {"export_animation": {"out": MP4, "size": 64, "preset": "draft"}}   (then {"wait_export": true})
  {"save_neural": PNG}                    the neural image as shown, once the latest request has a pass on screen
  {"screenshot": PNG}                     the whole window
  {"save_viewport": PNG}                  the viewport as shown (the Export panel's "Screenshot viewport")
  {"train": {"dataset": D, "out": O, "steps": N, "effects": E, "model": M}}  queue a training job
  {"from_video": {"video": V, "head": H, "landmarker": L, "out": O, "steps": N, "size": PX, "fps": F, "model": M}}
                                          queue a new avatar from a video (track, then train)
  {"reenact": {"video": V, "landmarker": L, "out": MP4, "size": PX, "seconds": S}}
                                          queue a reenactment of the open avatar by a performance video (its
                                          animation comes onto the timeline when done)
  {"wait_job": true}                      until no job is queued or running
  {"expect_open": FOLDER}                 fail unless the open avatar is FOLDER
  {"open_job": true}                      open the last job's avatar
  {"cancel_jobs": true}                   cancel every job (running ones checkpoint first)
  {"export": {"out": MP4, "frames": N, "size": PX, "preset": P, "animate": false, "sweep_deg": null}}
  {"wait_export": true}
  {"wait_frames": N}                      let N frames pass (frame-rate measurements)
  {"orbit": DX}                           orbit the camera as a mouse drag of DX pixels does
  {"live": SOURCE}                        drive the open avatar live from a camera ("0") or a video file in real time
  {"wait_live": FRAME}                    until the render of the source's frame FRAME (or a later one) is on screen
                                          (fails where live driving stops first)
  {"wait_live_end": true}                 until live driving stops (a video file ends)
  {"save_live": PNG}                      the live render on screen now (its source frame kept for the report's
                                          "live_log")
  {"stop_live": true}                     stop live driving
  {"live_neutral": true}                  the next face becomes the neutral one
  {"live_pass": PASS}                     the pass live poses render: auto, draft, preview or final
  {"live_guide": BOOL}                    whether the guide is drawn anew for every live pose
  {"record": true}                        record the live performance
  {"stop_recording": JSON}                stop: the recording onto the timeline and into the file
  {"expect_error": TEXT}                  fail unless a message in the window contains TEXT
  {"expect_warning": TEXT|null}           fail unless the viewport's warning contains TEXT (null: unless it has none)

A wait (wait_render, save_neural, wait_job, wait_export) fails after "timeout_s" seconds beside it (default WAIT_S)
without progress.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from PIL import Image

from app.jobs import JobQueue
from app.sliders import sliders_json
from app.studio import actions as a
from app.studio.exporting import Exporter
from app.studio.live import LiveFigures
from app.studio.neural import NeuralWorker
from app.studio.script_fields import (
    BOOL,
    COUNT,
    INTEGER,
    NUMBER,
    PATH,
    SECONDS,
    TEXT,
    TRUE,
    Checked,
    Kind,
    Record,
    ScriptError,
    StepSpec,
    check_script,
    either,
    one_of,
    optional,
    vector,
)
from app.studio.session import Session, views_warning
from app.studio.viewport import BUFFERS, Viewport
from app.turntable import TurntableConfig
from models.avatars.quality import PRESET_NAMES

WAIT_S = 300.0
"""How long a wait goes on without progress before the step fails (a step's "timeout_s" overrides it)."""


class Driven(Protocol):
    """What a script sees of the studio: the Session, its workers, and `act` (the same door the panels use)."""

    session: Session
    worker: NeuralWorker
    jobs: JobQueue
    exporter: Exporter
    viewport: Viewport
    last_submit_id: int
    latency_ms: float | None
    pass_latency_ms: dict[str, float]
    pass_render_ms: dict[str, float]
    live_figures: LiveFigures

    def act(self, action: a.Action | a.Command) -> None: ...

    def read_window(self) -> np.ndarray: ...


Step = Callable[["Script", Driven, dict], bool]
"""A step: True when it is done, False to be called again next frame (a wait)."""
STEPS: dict[str, Step] = {}
SPECS: dict[str, StepSpec] = {}
"""What each step's JSON holds (checked before the window opens)."""
WAIT = Record(optional={"timeout_s": SECONDS})
"""The field a wait takes beside its value."""


def step(key: str, value: Checked, beside: Record | None = None) -> Callable[[Step], Step]:
    """Register a step function for the JSON key that names it, with the kind of its value and the fields beside
    it."""
    def register(fn: Step) -> Step:
        STEPS[key] = fn
        SPECS[key] = StepSpec(value, beside or Record())
        return fn
    return register


@dataclass
class Script:
    steps: list[dict]
    report: Path | None = None
    index: int = 0
    failed: str = ""
    """Why the run stopped short: steps[INDEX] (ACTION): the problem ("" while it has not)."""
    waited_frames: int = 0
    wait_started: float = 0.0
    last_progress: object = None
    waiting_for: str = ""
    """What the wait in progress waits for (a wait for something else starts its own clock)."""
    pending_screenshot: Path | None = None
    ran: int = 0
    """Steps completed (the report's steps_run: every step runs once)."""
    log: list[str] = field(default_factory=list)
    latencies: list[dict[str, float]] = field(default_factory=list)
    sliders_log: list[dict] = field(default_factory=list)
    live_log: list[dict] = field(default_factory=list)
    """What each save_live step saved: the file and the source frame on screen."""
    """What each record_latency step saw."""

    @staticmethod
    def load(path: Path) -> Script:
        """The script in this file, every step checked (ScriptError: the first wrong one, with the file's name)."""
        try:
            data = json.loads(Path(path).read_text())
            check_script(data, SPECS)
        except json.JSONDecodeError as e:
            raise ScriptError(f"{path}: not JSON ({e})") from None
        except ScriptError as e:
            raise ScriptError(f"{path}: {e}") from None
        return Script(list(data["steps"]), Path(data["report"]) if data.get("report") else None)

    @property
    def over(self) -> bool:
        """Every step done, or one failed: the window closes."""
        return bool(self.failed) or (self.index >= len(self.steps) and self.pending_screenshot is None)

    @property
    def may_idle(self) -> bool:
        """The window may idle while the step waits on work outside its frames (a job, an export): the other steps
        need frames to go on."""
        return not self.over and self.pending_screenshot is None and any(
            k in self.steps[self.index] for k in ("wait_job", "wait_export"))

    def fail(self, message: str) -> bool:
        s = self.steps[self.index]
        action = next((k for k in s if k in STEPS), "?")
        self.failed = f"steps[{self.index}] ({action}): {message}"
        return False

    def _done(self) -> None:
        self.index += 1
        self.ran += 1
        self.waited_frames = 0
        self.wait_started = 0.0
        self.last_progress = None
        self.waiting_for = ""

    def waiting(self, condition: bool, progress: object = None, what: str = "", timeout_s: float | None = None
                ) -> bool:
        """True while the step must wait; fails it after timeout_s (the step's "timeout_s", else WAIT_S) seconds
        without `progress` changing (work that moves on, however slowly on a busy machine, is waited for). `what`:
        what it waits for, in the failure's message."""
        if condition:
            return False
        now = time.perf_counter()
        if timeout_s is None:
            timeout_s = float(self.steps[self.index].get("timeout_s", WAIT_S))
        moved = progress is not None and progress != self.last_progress
        if not self.wait_started or what != self.waiting_for or moved:
            self.wait_started, self.last_progress, self.waiting_for = now, progress, what
        elif now - self.wait_started > timeout_s:
            self.fail(f"{what or 'still waiting'} after {timeout_s:g} s"
                      + (" without progress" if progress is not None else ""))
        return True

    def step(self, studio: Driven) -> None:
        if self.over or self.pending_screenshot is not None:
            return
        opening = studio.session.opening
        if opening is not None:  # every step acts on the avatar being opened, once it is open
            self.waiting(False, what=f"{opening} still opening", timeout_s=WAIT_S)
            return
        s = self.steps[self.index]
        key = next(k for k in s if k in STEPS)  # load checked it
        try:
            done = STEPS[key](self, studio, s)
        except (KeyError, ValueError, TypeError, OSError) as e:  # the step's values do not fit what is open
            done = self.fail(e.args[0] if isinstance(e, KeyError) and e.args else str(e) or type(e).__name__)
        if done and not self.failed:
            self._done()

    def after_frame(self, studio: Driven) -> None:
        """Called with the frame complete (before it is shown): take a pending screenshot."""
        if self.pending_screenshot is not None:
            path, self.pending_screenshot = self.pending_screenshot, None
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(studio.read_window()).save(path)
            self._done()


def needs_avatar(st: Driven) -> None:
    """ValueError for a step that acts on the open avatar when none is."""
    if st.session.avatar is None:
        raise ValueError("no avatar is open" + (f" (last message: {st.session.errors[-1]})" if st.session.errors else
                                                ""))


def rendered(sc: Script, st: Driven, preset: str) -> bool:
    """Whether the latest request's pass `preset` (or a finer one) is on screen, in the buffer shown; a wait until
    it is (a renderer's error fails the step)."""
    needs_avatar(st)
    session, r = st.session, st.worker.result
    passes = list(PRESET_NAMES)
    if passes.index(preset) > passes.index(session.display.refine_to):
        raise ValueError(f"waits for the {preset} pass, but the viewport refines only to "
                         f"{session.display.refine_to} (a refine_to step before it sets that)")
    if st.worker.error:
        raise ValueError(f"the renderer failed: {st.worker.error}")
    ok = (not session.dirty and r is not None and r.request_id == st.last_submit_id
          and passes.index(r.pass_name) >= passes.index(preset) and st.viewport.neural_image is not None
          and st.viewport.shown == (r.request_id, r.pass_name, session.display.buffer))
    return not sc.waiting(ok, what="no render on screen" if preset == passes[0] else f"no {preset} pass on screen")


# ---- the steps ---------------------------------------------------------------------------------------------
@step("open", PATH)
def _open(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.OpenAvatar(Path(s["open"])))
    return True


@step("expression", Kind("an expression's name or index", either(TEXT, INTEGER).test), Record({"value": NUMBER}))
def _expression(sc: Script, st: Driven, s: dict) -> bool:
    needs_avatar(st)
    key, head = s["expression"], st.session.avatar.head_model
    i = key if isinstance(key, int) else head.expression_index(key)
    if not 0 <= i < head.num_expression:
        raise ValueError(f"no expression {i}: head model '{head.name}' has {head.num_expression} (0 to "
                         f"{head.num_expression - 1})")
    st.act(a.SetExpression(i, float(s["value"])))
    return True


@step("undo", TRUE)
def _undo(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.Undo())
    return True


@step("redo", TRUE)
def _redo(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.Undo(forward=True))
    return True


RESET_GROUPS = ("expression", "head", "neck", "jaw", "gaze", "camera")


@step("reset", Kind(f"a group ({', '.join(RESET_GROUPS)}, or expression:PART)",
                    lambda v: isinstance(v, str) and (v in RESET_GROUPS or v.startswith("expression:"))))
def _reset(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.ResetGroup(s["reset"]))
    return True


@step("record_sliders", TRUE)
def _record_sliders(sc: Script, st: Driven, s: dict) -> bool:
    sc.sliders_log.append({**sliders_json(st.session.sliders), "guide_draws": st.viewport.guide_draws})
    return True


@step("save_pose", TEXT)
def _save_pose(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SavePose(s["save_pose"]))
    return True


@step("recall_pose", TEXT)
def _recall_pose(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.RecallPose(s["recall_pose"]))
    return True


PIXELS = Kind("a size in pixels (an integer, 16 or more)", lambda v: INTEGER.test(v) and v >= 16)


@step("reenact", Record({"video": PATH, "landmarker": PATH, "out": PATH},
                        {"size": PIXELS, "seconds": optional(SECONDS)}))
def _reenact(sc: Script, st: Driven, s: dict) -> bool:
    r = s["reenact"]
    st.act(a.StartReenact(r["video"], r["landmarker"], r["out"], int(r.get("size", 256)), r.get("seconds")))
    return True


@step("jaw_open_deg", NUMBER)
def _jaw(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetJaw(float(s["jaw_open_deg"])))
    return True


@step("head", vector(3, "yaw, pitch, roll in degrees"))
def _head(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetAngles("head", tuple(float(v) for v in s["head"])))
    return True


@step("gaze", vector(2, "yaw, pitch in degrees"))
def _gaze(sc: Script, st: Driven, s: dict) -> bool:
    for eye in ("gaze_left", "gaze_right"):
        st.act(a.SetAngles(eye, tuple(float(v) for v in s["gaze"])))
    return True


@step("view", Record(optional={k: NUMBER for k in ("yaw_deg", "pitch_deg", "zoom", "fov_deg")}))
def _view(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetView(**s["view"]))
    return True


@step("buffer", one_of(BUFFERS))
def _buffer(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.ShowBuffer(s["buffer"]))
    return True


@step("timeline", Kind("a capture frame's index (-1: the sliders)", lambda v: INTEGER.test(v) and v >= -1))
def _timeline(sc: Script, st: Driven, s: dict) -> bool:
    needs_avatar(st)
    k, capture = s["timeline"], st.session.capture
    if k >= 0 and (capture is None or k >= len(capture.frames)):
        raise ValueError(f"no capture frame {k}: " + ("the avatar's capture is not on this machine" if capture is None
                                                      else f"its capture has {len(capture.frames)}"))
    st.act(a.ShowFrame(k))
    return True


@step("refine_to", one_of(PRESET_NAMES))
def _refine(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.RefineTo(s["refine_to"]))
    return True


@step("wait_render", one_of(PRESET_NAMES), WAIT)
def _wait_render(sc: Script, st: Driven, s: dict) -> bool:
    return rendered(sc, st, s["wait_render"])


@step("record_latency", TRUE)
def _record_latency(sc: Script, st: Driven, s: dict) -> bool:
    first = {} if st.latency_ms is None else {"first": st.latency_ms}
    sc.latencies.append({**first, **st.pass_latency_ms, **{f"{k} render": v for k, v in st.pass_render_ms.items()}})
    return True


@step("save_neural", PATH, WAIT)
def _save_neural(sc: Script, st: Driven, s: dict) -> bool:
    if not rendered(sc, st, PRESET_NAMES[0]):  # the latest request's first pixels, whichever pass
        return False
    path = Path(s["save_neural"])
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(st.viewport.neural_image).save(path)
    return True


@step("save_viewport", PATH)
def _save_viewport(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SaveViewport(Path(s["save_viewport"])))  # written when this frame is drawn
    return True


@step("screenshot", PATH)
def _screenshot(sc: Script, st: Driven, s: dict) -> bool:
    sc.pending_screenshot = Path(s["screenshot"])  # read after this frame is drawn (after_frame ends the step)
    return False


TRAINING = {"effects": TEXT, "model": TEXT, "minutes": SECONDS, "steps": COUNT}


@step("train", Record({"dataset": PATH, "out": PATH}, TRAINING))
def _train(sc: Script, st: Driven, s: dict) -> bool:
    t = s["train"]
    st.act(a.StartTraining(t["dataset"], t["out"], t.get("model", "codynerf"), t.get("effects", "none"),
                           t.get("minutes"), t.get("steps")))
    return True


@step("from_video", Record({"video": PATH, "landmarker": PATH, "out": PATH},
                           {**TRAINING, "head": TEXT, "size": PIXELS, "fps": optional(NUMBER)}))
def _from_video(sc: Script, st: Driven, s: dict) -> bool:
    v = s["from_video"]
    st.act(a.StartFromVideo(v["video"], v.get("head", "builtin"), v["landmarker"], v["out"], v.get("effects", "none"),
                            v.get("minutes"), v.get("steps"), int(v.get("size", 256)), v.get("fps"),
                            v.get("model")))
    return True


@step("expect_open", PATH)
def _expect_open(sc: Script, st: Driven, s: dict) -> bool:
    folder = st.session.folder
    if folder is None or Path(folder).resolve() != Path(s["expect_open"]).resolve():
        return sc.fail(f"open avatar is {folder}, not {s['expect_open']}")
    return True


@step("wait_job", TRUE, WAIT)
def _wait_job(sc: Script, st: Driven, s: dict) -> bool:
    """Until every job is done; a job whose log or progress moves is not timed out."""
    busy = [j for j in st.jobs.jobs if j.state in ("queued", "running")]
    progress = tuple((j.id, j.stage, len(j.progress), _log_size(j)) for j in busy)
    return not sc.waiting(not busy, progress, what="jobs still running")


def _log_size(job) -> int:
    try:
        return job.log_path.stat().st_size  # tracking writes its progress there
    except OSError:
        return 0


@step("cancel_jobs", TRUE)
def _cancel_jobs(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.CancelJob(None))
    return True


@step("open_job", TRUE)
def _open_job(sc: Script, st: Driven, s: dict) -> bool:
    if not st.jobs.jobs:
        raise ValueError("no job was started")
    st.act(a.OpenAvatar(st.jobs.jobs[-1].out))
    return True


@step("export", Record({"out": PATH}, {"frames": COUNT, "size": PIXELS, "preset": one_of(PRESET_NAMES),
                                       "animate": BOOL, "sweep_deg": optional(NUMBER)}))
def _export(sc: Script, st: Driven, s: dict) -> bool:
    needs_avatar(st)
    x = s["export"]
    size = int(x.get("size", 64))
    cfg = TurntableConfig(st.session.folder, Path(x["out"]), frames=max(1, int(x.get("frames", 12))),
                          sweep_deg=x.get("sweep_deg"), size=max(16, size - size % 2),
                          preset=x.get("preset", "draft"), animate=bool(x.get("animate", False)))
    st.act(a.ExportTurntable(cfg))
    return True


@step("wait_export", TRUE, WAIT)
def _wait_export(sc: Script, st: Driven, s: dict) -> bool:
    return not sc.waiting(not st.exporter.running, what="the export still running")


@step("orbit", NUMBER)
def _orbit(sc: Script, st: Driven, s: dict) -> bool:  # a mouse drag of dx pixels, as the viewport applies it
    st.act(a.Orbit(float(s["orbit"])))
    return True


@step("key", TRUE)
def _key(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.KeyPose())
    return True


@step("seek", SECONDS)
def _seek(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SeekAnimation(float(s["seek"])))
    return True


@step("play", BOOL)
def _play(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.PlayAnimation(bool(s["play"])))
    return True


@step("save_animation", PATH)
def _save_animation(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SaveAnimation(Path(s["save_animation"])))
    return True


@step("load_animation", PATH)
def _load_animation(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.LoadAnimation(Path(s["load_animation"])))
    return True


@step("export_animation", Record({"out": PATH}, {"size": PIXELS, "preset": one_of(PRESET_NAMES)}))
def _export_animation(sc: Script, st: Driven, s: dict) -> bool:
    x = s["export_animation"]
    st.act(a.ExportAnimation(Path(x["out"]), int(x.get("size", 64)), x.get("preset", "draft")))
    return True


@step("wait_frames", COUNT)
def _wait_frames(sc: Script, st: Driven, s: dict) -> bool:
    sc.waited_frames += 1
    return sc.waited_frames >= int(s["wait_frames"])


@step("expect_error", TEXT)
def _expect_error(sc: Script, st: Driven, s: dict) -> bool:
    shown = [*st.session.errors, st.session.job_message]  # the Avatar panel's messages, the Jobs panel's
    if not any(s["expect_error"] in e for e in shown):
        return sc.fail(f"no message containing {s['expect_error']!r} (messages: {shown})")
    return True


@step("expect_warning", optional(TEXT))
def _expect_warning(sc: Script, st: Driven, s: dict) -> bool:
    warning, expected = views_warning(st.session), s["expect_warning"]
    if expected is None and warning:
        return sc.fail(f"the viewport warns: {warning}")
    if expected is not None and expected not in warning:
        return sc.fail(f"no viewport warning containing {expected!r} (it shows: {warning or 'none'})")
    return True



@step("live", TEXT)
def _live(sc: Script, st: Driven, s: dict) -> bool:
    needs_avatar(st)
    st.act(a.StartLive(s["live"]))
    return True


@step("wait_live", COUNT, WAIT)
def _wait_live(sc: Script, st: Driven, s: dict) -> bool:
    shown, live = st.live_figures.on_screen, st.session.live
    if shown < s["wait_live"] and not live.running:
        raise ValueError(f"live driving stopped at frame {shown}" + (f": {live.message}" if live.message else ""))
    return not sc.waiting(shown >= s["wait_live"], shown, what=f"frame {s['wait_live']} of the live source not shown")


@step("wait_live_end", TRUE, WAIT)
def _wait_live_end(sc: Script, st: Driven, s: dict) -> bool:
    return not sc.waiting(not st.session.live.running, st.live_figures.on_screen, what="live driving still running")


@step("live_neutral", TRUE)
def _live_neutral(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.LiveNeutral())
    return True


@step("record", TRUE)
def _record(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.StartRecording())
    return True


@step("stop_recording", PATH)
def _stop_recording(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.StopRecording(Path(s["stop_recording"])))
    return True


@step("save_live", PATH)
def _save_live(sc: Script, st: Driven, s: dict) -> bool:
    if st.viewport.neural_image is None or st.live_figures.on_screen < 0:
        raise ValueError("no live render on screen (a live step, then wait_live, before it)")
    path = Path(s["save_live"])
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(st.viewport.neural_image).save(path)
    sc.live_log.append({"file": str(path), "frame": st.live_figures.on_screen,
                        "sliders": sliders_json(st.session.sliders)})
    return True


@step("live_pass", one_of(("auto", *PRESET_NAMES)))
def _live_pass(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetDisplay({"live_pass": s["live_pass"]}))
    return True


@step("live_guide", BOOL)
def _live_guide(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetDisplay({"live_guide": s["live_guide"]}))
    return True


@step("stop_live", TRUE)
def _stop_live(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.StopLive())
    return True
