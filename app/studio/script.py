"""Scripted studio runs: a JSON file {"report": PATH, "steps": [...]} whose steps act through the same code
the widgets call, one step per frame, with waits that keep the window drawing (tests under Xvfb, README
pictures). Steps:

  {"open": FOLDER}                        open an avatar (errors land in the window's messages)
  {"expression": NAME|INDEX, "value": W}  move an expression slider
  {"jaw_open_deg": D}                     open the jaw, degrees
  {"head": [YAW, PITCH, ROLL]}            turn the head, degrees
  {"gaze": [YAW, PITCH]}                  turn both eyes, degrees
  {"view": {"yaw_deg": ...}}              the orbit camera (yaw_deg, pitch_deg, zoom, fov_deg)
  {"buffer": NAME}                        the neural buffer on screen
  {"timeline": FRAME}                     show a capture frame's controls (-1: the sliders)
  {"refine_to": PRESET}                   the pass the viewport refines to
  {"wait_render": PRESET}                 until the latest request's pass PRESET is on screen
  {"record_latency": true}                the ms from the last change to its first pixels ("first") and to each
                                          of its passes' pixels (passes a faster finer one made pointless are
                                          left out: app/studio/neural.py), and as "PASS render" each pass's own
                                          render time, kept for the report's
                                          "latencies" (benchmarks/bench_studio.py)
  {"undo": true}                          undo the last slider or camera change (Ctrl+Z)
  {"redo": true}                          redo it (Ctrl+Shift+Z)
  {"reset": GROUP}                        a group back to rest: expression[:brows|eyes|mouth|...], head, neck, jaw,
                                          gaze, camera
  {"record_sliders": true}               keep the sliders' values now, for the report's "sliders_log"
  {"save_pose": NAME}                     save the sliders as a named pose of this avatar
  {"recall_pose": NAME}                   set the sliders to a named pose
  {"key": true}                           key the pose at the animation's time (Animation tab's "Key pose")
  {"seek": SECONDS}                       move along the animation (its keyed channels set the sliders)
  {"play": BOOL}                          play or stop the animation
  {"save_animation": JSON}                save the animation's keys
  {"load_animation": JSON}                load an animation's keys
  {"export_animation": {"out": MP4, "size": 64, "preset": "draft"}}   (then {"wait_export": true})
  {"save_neural": PNG}                    the neural image as shown
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
  {"expect_error": TEXT}                  fail unless a message in the window contains TEXT
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from imgui_bundle import hello_imgui
from PIL import Image

from app.jobs import JobQueue
from app.sliders import sliders_json
from app.studio import actions as a
from app.studio.exporting import Exporter
from app.studio.neural import NeuralWorker
from app.studio.session import Session
from app.studio.viewport import Viewport
from app.turntable import TurntableConfig
from models.avatars.quality import PRESET_NAMES

WAIT_S = 300.0


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

    def act(self, action: a.Action | a.Command) -> None: ...

    def read_window(self) -> np.ndarray: ...


Step = Callable[["Script", Driven, dict], bool]
"""A step: True when it is done, False to be called again next frame (a wait)."""
STEPS: dict[str, Step] = {}


def step(key: str) -> Callable[[Step], Step]:
    """Register a step function for the JSON key that names it."""
    def register(fn: Step) -> Step:
        STEPS[key] = fn
        return fn
    return register


@dataclass
class Script:
    steps: list[dict]
    report: Path | None = None
    index: int = 0
    failed: str = ""
    waited_frames: int = 0
    wait_started: float = 0.0
    last_progress: object = None
    pending_screenshot: Path | None = None
    ran: int = 0
    """Steps completed (the report's steps_run: every step runs once)."""
    log: list[str] = field(default_factory=list)
    latencies: list[dict[str, float]] = field(default_factory=list)
    sliders_log: list[dict] = field(default_factory=list)
    """What each record_latency step saw."""

    @staticmethod
    def load(path: Path) -> Script:
        data = json.loads(Path(path).read_text())
        return Script(list(data["steps"]), Path(data["report"]) if data.get("report") else None)

    def fail(self, message: str) -> bool:
        self.failed = f"step {self.index} {self.steps[self.index]}: {message}"
        hello_imgui.get_runner_params().app_shall_exit = True
        return False

    def _done(self) -> None:
        self.index += 1
        self.ran += 1
        self.waited_frames = 0
        self.wait_started = 0.0

    def waiting(self, condition: bool, progress: object = None) -> bool:
        """True while the step must wait; fails it after WAIT_S seconds without `progress` changing (work that
        moves on, however slowly on a busy machine, is waited for)."""
        if condition:
            return False
        now = time.perf_counter()
        if not self.wait_started or (progress is not None and progress != self.last_progress):
            self.wait_started, self.last_progress = now, progress
        elif now - self.wait_started > WAIT_S:
            self.fail(f"still waiting after {WAIT_S:.0f} s" + (" without progress" if progress is not None else ""))
        return True

    def step(self, studio: Driven) -> None:
        if self.failed or self.pending_screenshot is not None:
            return
        if self.waiting(studio.session.opening is None):  # every step acts on the avatar being opened, once open
            return
        if self.index >= len(self.steps):
            hello_imgui.get_runner_params().app_shall_exit = True
            return
        s = self.steps[self.index]
        key = next((k for k in s if k in STEPS), None)
        if key is None:
            self.fail("unknown step")
            return
        if STEPS[key](self, studio, s) and not self.failed:
            self._done()

    def after_frame(self, studio: Driven) -> None:
        """Called with the frame complete (before it is shown): take a pending screenshot."""
        if self.pending_screenshot is not None:
            path, self.pending_screenshot = self.pending_screenshot, None
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(studio.read_window()).save(path)
            self._done()


# ---- the steps ---------------------------------------------------------------------------------------------
@step("open")
def _open(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.OpenAvatar(Path(s["open"])))
    return True


@step("expression")
def _expression(sc: Script, st: Driven, s: dict) -> bool:
    key = s["expression"]
    i = key if isinstance(key, int) else st.session.avatar.head_model.expression_index(key)
    st.act(a.SetExpression(i, float(s["value"])))
    return True


@step("undo")
def _undo(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.Undo())
    return True


@step("redo")
def _redo(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.Undo(forward=True))
    return True


@step("reset")
def _reset(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.ResetGroup(s["reset"]))
    return True


@step("record_sliders")
def _record_sliders(sc: Script, st: Driven, s: dict) -> bool:
    sc.sliders_log.append(sliders_json(st.session.sliders))
    return True


@step("save_pose")
def _save_pose(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SavePose(s["save_pose"]))
    return True


@step("recall_pose")
def _recall_pose(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.RecallPose(s["recall_pose"]))
    return True


@step("reenact")
def _reenact(sc: Script, st: Driven, s: dict) -> bool:
    r = s["reenact"]
    st.act(a.StartReenact(r["video"], r["landmarker"], r["out"], int(r.get("size", 256)), r.get("seconds")))
    return True


@step("jaw_open_deg")
def _jaw(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetJaw(float(s["jaw_open_deg"])))
    return True


@step("head")
def _head(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetAngles("head", tuple(float(v) for v in s["head"])))
    return True


@step("gaze")
def _gaze(sc: Script, st: Driven, s: dict) -> bool:
    for eye in ("gaze_left", "gaze_right"):
        st.act(a.SetAngles(eye, tuple(float(v) for v in s["gaze"])))
    return True


@step("view")
def _view(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SetView(**s["view"]))
    return True


@step("buffer")
def _buffer(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.ShowBuffer(s["buffer"]))
    return True


@step("timeline")
def _timeline(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.ShowFrame(int(s["timeline"])))
    return True


@step("refine_to")
def _refine(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.RefineTo(s["refine_to"]))
    return True


@step("wait_render")
def _wait_render(sc: Script, st: Driven, s: dict) -> bool:
    r, session = st.worker.result, st.session
    target = list(PRESET_NAMES).index(s["wait_render"])
    ok = (not session.dirty and r is not None and r.request_id == st.last_submit_id
          and list(PRESET_NAMES).index(r.pass_name) >= target and st.viewport.neural_image is not None
          and st.viewport.shown == (r.request_id, r.pass_name, session.display.buffer))
    if sc.waiting(ok or bool(st.worker.error)):
        return False
    return sc.fail(st.worker.error) if st.worker.error else True


@step("record_latency")
def _record_latency(sc: Script, st: Driven, s: dict) -> bool:
    first = {} if st.latency_ms is None else {"first": st.latency_ms}
    sc.latencies.append({**first, **st.pass_latency_ms, **{f"{k} render": v for k, v in st.pass_render_ms.items()}})
    return True


@step("save_neural")
def _save_neural(sc: Script, st: Driven, s: dict) -> bool:
    path = Path(s["save_neural"])
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(st.viewport.neural_image).save(path)
    return True


@step("save_viewport")
def _save_viewport(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SaveViewport(Path(s["save_viewport"])))  # written when this frame is drawn
    return True


@step("screenshot")
def _screenshot(sc: Script, st: Driven, s: dict) -> bool:
    sc.pending_screenshot = Path(s["screenshot"])  # read after this frame is drawn (after_frame ends the step)
    return False


@step("train")
def _train(sc: Script, st: Driven, s: dict) -> bool:
    t = s["train"]
    st.act(a.StartTraining(t["dataset"], t["out"], t.get("model", "codynerf"), t.get("effects", "none"),
                           t.get("minutes"), t.get("steps")))
    return True


@step("from_video")
def _from_video(sc: Script, st: Driven, s: dict) -> bool:
    v = s["from_video"]
    st.act(a.StartFromVideo(v["video"], v.get("head", "builtin"), v["landmarker"], v["out"], v.get("effects", "none"),
                            v.get("minutes"), v.get("steps"), int(v.get("size", 256)), v.get("fps"),
                            v.get("model")))
    return True


@step("expect_open")
def _expect_open(sc: Script, st: Driven, s: dict) -> bool:
    folder = st.session.folder
    if folder is None or Path(folder).resolve() != Path(s["expect_open"]).resolve():
        return sc.fail(f"open avatar is {folder}, not {s['expect_open']}")
    return True


@step("wait_job")
def _wait_job(sc: Script, st: Driven, s: dict) -> bool:
    """Until every job is done; a job whose log or progress moves is not timed out."""
    busy = [j for j in st.jobs.jobs if j.state in ("queued", "running")]
    progress = tuple((j.id, j.stage, len(j.progress), _log_size(j)) for j in busy)
    return not sc.waiting(not busy, progress)


def _log_size(job) -> int:
    try:
        return job.log_path.stat().st_size  # tracking writes its progress there
    except OSError:
        return 0


@step("cancel_jobs")
def _cancel_jobs(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.CancelJob(None))
    return True


@step("open_job")
def _open_job(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.OpenAvatar(st.jobs.jobs[-1].out))
    return True


@step("export")
def _export(sc: Script, st: Driven, s: dict) -> bool:
    x = s["export"]
    size = int(x.get("size", 64))
    cfg = TurntableConfig(st.session.folder, Path(x["out"]), frames=max(1, int(x.get("frames", 12))),
                          sweep_deg=x.get("sweep_deg"), size=max(16, size - size % 2),
                          preset=x.get("preset", "draft"), animate=bool(x.get("animate", False)))
    st.act(a.ExportTurntable(cfg))
    return True


@step("wait_export")
def _wait_export(sc: Script, st: Driven, s: dict) -> bool:
    return not sc.waiting(not st.exporter.running)


@step("orbit")
def _orbit(sc: Script, st: Driven, s: dict) -> bool:  # a mouse drag of dx pixels, as the viewport applies it
    st.act(a.Orbit(float(s["orbit"])))
    return True


@step("key")
def _key(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.KeyPose())
    return True


@step("seek")
def _seek(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SeekAnimation(float(s["seek"])))
    return True


@step("play")
def _play(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.PlayAnimation(bool(s["play"])))
    return True


@step("save_animation")
def _save_animation(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.SaveAnimation(Path(s["save_animation"])))
    return True


@step("load_animation")
def _load_animation(sc: Script, st: Driven, s: dict) -> bool:
    st.act(a.LoadAnimation(Path(s["load_animation"])))
    return True


@step("export_animation")
def _export_animation(sc: Script, st: Driven, s: dict) -> bool:
    x = s["export_animation"]
    st.act(a.ExportAnimation(Path(x["out"]), int(x.get("size", 64)), x.get("preset", "draft")))
    return True


@step("wait_frames")
def _wait_frames(sc: Script, st: Driven, s: dict) -> bool:
    sc.waited_frames += 1
    return sc.waited_frames >= int(s["wait_frames"])


@step("expect_error")
def _expect_error(sc: Script, st: Driven, s: dict) -> bool:
    shown = [*st.session.errors, st.session.job_message]  # the Avatar panel's messages, the Jobs panel's
    if not any(s["expect_error"] in e for e in shown):
        return sc.fail(f"no message containing {s['expect_error']!r} (messages: {shown})")
    return True
