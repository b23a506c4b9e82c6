"""The Live section (top of the Controls panel): drive the open avatar from a camera (its OpenCV index) or a video
file played in real time, take a new neutral face, record the performance onto the timeline (and into a file that
`avatar-studio animate` reads), and what live driving measures: poses tracked, frames dropped, the latency from a
camera frame to its pixels on screen."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from imgui_bundle import imgui

from app.studio import actions as a
from app.studio.config import STUDIO_HOME
from app.studio.context import PanelContext


class PanelState:
    source = "0"
    record_to = str(STUDIO_HOME / "live" / "performance.json")


def draw(ctx: PanelContext) -> None:
    s, act, live = ctx.session, ctx.act, ctx.session.live
    if not imgui.collapsing_header("Live", imgui.TreeNodeFlags_.default_open):
        return
    if not live.running:
        imgui.set_next_item_width(180)
        _, PanelState.source = imgui.input_text("camera or video##live_source", PanelState.source)
        if imgui.is_item_hovered():
            imgui.set_tooltip("a camera's index (0 is the first camera) or a video file, played in real time")
        imgui.same_line()
        if imgui.button("Go live") and s.avatar is not None:
            act(a.StartLive(PanelState.source))
        if live.message:
            imgui.text_disabled(live.message)
        return
    if imgui.button("Stop live"):
        act(a.StopLive())
    imgui.same_line()
    if imgui.button("Neutral now"):
        act(a.LiveNeutral())
    if imgui.is_item_hovered():
        imgui.set_tooltip("the face shown next becomes the avatar's rest (hold a relaxed face)")
    imgui.same_line()
    if not live.recording:
        if imgui.button("Record"):
            act(a.StartRecording())
    elif imgui.button("Stop recording"):
        act(a.StopRecording(_record_path()))
    imgui.set_next_item_width(260)
    _, PanelState.record_to = imgui.input_text("save to##live_record", PanelState.record_to)
    choices = ("auto", "draft", "preview", "final")
    imgui.set_next_item_width(120)
    changed, k = imgui.combo("live quality", choices.index(s.display.live_pass), list(choices))
    if changed:
        act(a.SetDisplay({"live_pass": choices[k]}))
    if imgui.is_item_hovered():
        imgui.set_tooltip("auto: the finest pass that keeps up with the camera; a preset: that one, however slow")
    imgui.same_line()
    changed, follows = imgui.checkbox("guide follows", s.display.live_guide)
    if changed:
        act(a.SetDisplay({"live_guide": follows}))
    if imgui.is_item_hovered():
        imgui.set_tooltip("draw the guide anew for every live pose: on a machine without a GPU its drawing delays "
                          "the avatar's pixels (about 50 ms here)")
    f = ctx.live
    if f is not None:
        recent = f.latency_ms[-30:]
        latency = f"{np.median(recent):.0f} ms" if recent else "-"
        imgui.text_disabled(f"{live.source}: frame {live.index}, {f.poses} tracked, {f.dropped} dropped; "
                            f"camera to pixels {latency}" + (" (recording)" if live.recording else ""))


def _record_path() -> Path:
    """Where a finished recording is saved: the field's path, with the time in its name where that file exists."""
    path = Path(PanelState.record_to.strip() or STUDIO_HOME / "live" / "performance.json").expanduser()
    if path.exists():
        path = path.with_name(f"{path.stem}_{time.strftime('%Y%m%d_%H%M%S')}{path.suffix or '.json'}")
    return path
