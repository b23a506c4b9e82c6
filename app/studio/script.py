"""Scripted studio runs: a JSON file {"report": PATH, "steps": [...]} whose steps act through the same code
the widgets call, one step per frame, with waits that keep the window drawing (tests under Xvfb, README
pictures). Steps:

  {"open": FOLDER}                        open an avatar (errors land in the window's messages)
  {"expression": NAME|INDEX, "value": W}  move an expression slider
  {"jaw_open_deg": D} / {"head": [YAW, PITCH, ROLL]} / {"view": {"yaw_deg": ...}} / {"buffer": NAME}
  {"timeline": FRAME}                     show a capture frame's controls (-1: the sliders)
  {"refine_to": PRESET}                   the pass the viewport refines to
  {"wait_render": PRESET}                 until the latest request's pass PRESET is on screen
  {"save_neural": PNG} / {"screenshot": PNG}   the neural image as shown / the whole window
  {"train": {"dataset": D, "out": O, "steps": N, "effects": E, "model": M}}  queue a training job
  {"from_video": {"video": V, "head": H, "landmarker": L, "out": O, "steps": N, "size": PX, "fps": F}}
                                          queue a new avatar from a video (track, then train)
  {"wait_job": true}                      until no job is queued or running
  {"expect_open": FOLDER}                 fail unless the open avatar is FOLDER
  {"open_job": true}                      open the last job's avatar
  {"cancel_jobs": true}                   cancel every job (running ones checkpoint first)
  {"export": {"out": MP4, "frames": N, "size": PX, "preset": P, "animate": false}}
  {"wait_export": true}
  {"wait_frames": N}                      let N frames pass (frame-rate measurements)
  {"orbit": DX}                           orbit the camera as a mouse drag of DX pixels does
  {"expect_error": TEXT}                  fail unless a message in the window contains TEXT
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from imgui_bundle import hello_imgui
from PIL import Image

from models.avatars.quality import PRESET_NAMES

if TYPE_CHECKING:
    from app.studio.app import Studio

WAIT_S = 300.0


@dataclass
class Script:
    steps: list[dict]
    report: Path | None = None
    index: int = 0
    failed: str = ""
    waited_frames: int = 0
    wait_started: float = 0.0
    pending_screenshot: Path | None = None
    log: list[str] = field(default_factory=list)

    @staticmethod
    def load(path: Path) -> Script:
        data = json.loads(Path(path).read_text())
        return Script(list(data["steps"]), Path(data["report"]) if data.get("report") else None)

    def _fail(self, message: str) -> None:
        self.failed = f"step {self.index} {self.steps[self.index]}: {message}"
        hello_imgui.get_runner_params().app_shall_exit = True

    def _done(self) -> None:
        self.index += 1
        self.waited_frames = 0
        self.wait_started = 0.0

    def _waiting(self, condition: bool) -> bool:
        """True while the step must wait; fails it after WAIT_S seconds."""
        if condition:
            return False
        if not self.wait_started:
            self.wait_started = time.perf_counter()
        elif time.perf_counter() - self.wait_started > WAIT_S:
            self._fail(f"still waiting after {WAIT_S:.0f} s")
        return True

    def step(self, studio: Studio) -> None:
        if self.failed or self.pending_screenshot is not None:
            return
        if self._waiting(studio.opening is None):  # every step acts on the avatar being opened, once it is open
            return
        if self.index >= len(self.steps):
            hello_imgui.get_runner_params().app_shall_exit = True
            return
        s = self.steps[self.index]
        sl = studio.session.sliders
        if "open" in s:
            studio.open_avatar(s["open"])
        elif "expression" in s:
            head = studio.session.avatar.head_model
            key = s["expression"]
            i = key if isinstance(key, int) else head.expression_index(key)
            sl.expression[i] = float(s["value"])
            studio.timeline_frame = -1
            studio.dirty = True
        elif "jaw_open_deg" in s:
            sl.jaw_open_deg = float(s["jaw_open_deg"])
            studio.dirty = True
        elif "head" in s:
            sl.head[:] = np.asarray(s["head"], np.float32)
            studio.dirty = True
        elif "view" in s:
            for k, v in s["view"].items():
                setattr(studio.view, k, v)
            studio.dirty = True
        elif "buffer" in s:
            from app.studio.viewport import INSPECT

            if s["buffer"] in INSPECT and studio.buffer not in INSPECT:
                studio.dirty = True  # as the combo does: render again with the variants the buffer is made of
            studio.buffer = s["buffer"]
        elif "timeline" in s:
            studio.timeline_frame = int(s["timeline"])
            studio.dirty = True
        elif "refine_to" in s:
            studio.refine_to = s["refine_to"]
            studio.dirty = True
        elif "wait_render" in s:
            r = studio.worker.result
            target = list(PRESET_NAMES).index(s["wait_render"])
            ok = (not studio.dirty and r is not None and r.request_id == studio.last_submit_id
                  and list(PRESET_NAMES).index(r.pass_name) >= target and studio.viewport.neural_image is not None
                  and studio.viewport.shown == (r.request_id, r.pass_name, studio.buffer))
            if self._waiting(ok or bool(studio.worker.error)):
                return
            if studio.worker.error:
                return self._fail(studio.worker.error)
        elif "save_neural" in s:
            path = Path(s["save_neural"])
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(studio.viewport.neural_image).save(path)
        elif "screenshot" in s:
            self.pending_screenshot = Path(s["screenshot"])  # read after this frame is drawn
        elif "train" in s:
            from app.studio.jobs_panel import start

            t = s["train"]
            start(studio, t["dataset"], t["out"], t.get("model", "codynerf"), t.get("effects", "none"),
                  t.get("minutes"), t.get("steps"))
        elif "from_video" in s:
            from app.studio.jobs_panel import start_from_video

            v = s["from_video"]
            start_from_video(studio, v["video"], v.get("head", "builtin"), v["landmarker"], v["out"],
                             v.get("effects", "none"), v.get("minutes"), v.get("steps"), int(v.get("size", 256)),
                             float(v.get("fps", 10.0)))
        elif "expect_open" in s:
            folder = studio.session.folder
            if folder is None or Path(folder).resolve() != Path(s["expect_open"]).resolve():
                return self._fail(f"open avatar is {studio.session.folder}, not {s['expect_open']}")
        elif "wait_job" in s:
            if self._waiting(not any(j.state in ("queued", "running") for j in studio.jobs.jobs)):
                return
        elif "cancel_jobs" in s:
            for job in studio.jobs.jobs:
                studio.jobs.cancel(job)
        elif "open_job" in s:
            studio.open_avatar(studio.jobs.jobs[-1].out)
        elif "export" in s:
            from app.studio.export_panel import export_turntable

            e, x = studio.export, s["export"]
            e.out, e.frames, e.size = x["out"], int(x.get("frames", 12)), int(x.get("size", 64))
            e.preset = list(PRESET_NAMES).index(x.get("preset", "draft"))
            e.animate = bool(x.get("animate", False))
            export_turntable(studio)
        elif "wait_export" in s:
            if self._waiting(not studio.export.running):
                return
        elif "orbit" in s:  # a mouse drag of dx pixels, as the viewport applies it
            studio.view.orbit(float(s["orbit"]), 0.0)
            studio.dirty = True
        elif "wait_frames" in s:
            self.waited_frames += 1
            if self.waited_frames < int(s["wait_frames"]):
                return
        elif "expect_error" in s:
            if not any(s["expect_error"] in e for e in studio.errors):
                return self._fail(f"no message containing {s['expect_error']!r} (messages: {studio.errors})")
        else:
            return self._fail("unknown step")
        self._done()

    def after_frame(self, studio: Studio) -> None:
        """Called with the frame complete (before it is shown): take a pending screenshot."""
        if self.pending_screenshot is not None:
            path, self.pending_screenshot = self.pending_screenshot, None
            path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(studio.read_window()).save(path)
            self._done()
