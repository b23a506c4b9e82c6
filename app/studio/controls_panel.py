"""The Controls panel: every expression component (named where the head model names them; a filter box),
head pose, neck, jaw, gaze (linked or each eye), the camera orbit, resets, and a timeline over the
capture's frames that loads a frame's controls and shows its image beside the render."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from imgui_bundle import imgui

from app.studio.session import Sliders, View

if TYPE_CHECKING:
    from app.studio.app import Studio


class PanelState:
    filter_text = ""


def _angles(label: str, values: np.ndarray, names: tuple[str, ...], limit: float) -> bool:
    changed = False
    for i, n in enumerate(names):
        c, v = imgui.slider_float(f"{n}##{label}", float(values[i]), -limit, limit, "%.1f deg")
        if c:
            values[i] = v
            changed = True
    return changed


def draw(studio: Studio) -> None:
    s = studio.session
    if s.avatar is None:
        imgui.text("Open an avatar to drive it.")
        return
    sl = s.sliders
    head = s.avatar.head_model
    changed = False

    if s.capture is not None and s.capture.frames:
        n = len(s.capture.frames)
        imgui.text("Timeline (capture frames; -1: the sliders)")
        c, k = imgui.slider_int("frame", studio.timeline_frame, -1, n - 1)
        if c:
            studio.timeline_frame = k
            studio.dirty = True
        if studio.timeline_frame >= 0 and imgui.button("Copy this frame to the sliders"):
            s.sliders = Sliders.of(s.capture.frames[studio.timeline_frame].controls, head.num_expression)
            studio.timeline_frame = -1
            changed = True
    elif s.capture_note:
        imgui.text_wrapped(s.capture_note)
    if studio.timeline_frame >= 0:
        imgui.text_wrapped("Showing a capture frame: the sliders below take over when you move them.")

    if imgui.collapsing_header("Expression", imgui.TreeNodeFlags_.default_open):
        if imgui.button("Reset expression"):
            sl.expression[:] = 0
            changed = True
        imgui.same_line()
        imgui.set_next_item_width(140)
        _, PanelState.filter_text = imgui.input_text("filter", PanelState.filter_text)
        needle = PanelState.filter_text.lower()
        for i in range(head.num_expression):
            name = head.expr_names[i] if i < len(head.expr_names) else f"expression {i}"
            if needle and needle not in name.lower():
                continue
            c, v = imgui.slider_float(name, float(sl.expression[i]), -1.0, 1.5, "%.2f")
            if c:
                sl.expression[i] = v
                changed = True
    if imgui.collapsing_header("Head and neck", imgui.TreeNodeFlags_.default_open):
        if imgui.button("Reset pose"):
            sl.head[:] = 0
            sl.neck[:] = 0
            changed = True
        changed |= _angles("head", sl.head, ("head yaw", "head pitch", "head roll"), 60)
        if "neck" in head.joint_names:
            changed |= _angles("neck", sl.neck, ("neck yaw", "neck pitch", "neck roll"), 45)
    if "jaw" in head.joint_names and imgui.collapsing_header("Jaw", imgui.TreeNodeFlags_.default_open):
        c, v = imgui.slider_float("jaw open", sl.jaw_open_deg, -5.0, 30.0, "%.1f deg")
        if c:
            sl.jaw_open_deg = v
            changed = True
    if {"eye_l", "eye_r"} <= set(head.joint_names) and imgui.collapsing_header("Gaze"):
        c, sl.gaze_linked = imgui.checkbox("both eyes together", sl.gaze_linked)
        changed |= c
        changed |= _angles("gl", sl.gaze_left, ("gaze yaw" if sl.gaze_linked else "left yaw",
                                                "gaze pitch" if sl.gaze_linked else "left pitch"), 30)
        if not sl.gaze_linked:
            changed |= _angles("gr", sl.gaze_right, ("right yaw", "right pitch"), 30)
        if imgui.button("Reset gaze"):
            sl.gaze_left[:] = 0
            sl.gaze_right[:] = 0
            changed = True
    if imgui.collapsing_header("Camera", imgui.TreeNodeFlags_.default_open):
        v = studio.view
        moved = False
        c, v.yaw_deg = imgui.slider_float("orbit yaw", v.yaw_deg, -180, 180, "%.0f deg")
        moved |= c
        c, v.pitch_deg = imgui.slider_float("orbit pitch", v.pitch_deg, -85, 85, "%.0f deg")
        moved |= c
        c, v.zoom = imgui.slider_float("zoom", v.zoom, 0.25, 8.0, "%.2fx", imgui.SliderFlags_.logarithmic)
        moved |= c
        c, v.fov_deg = imgui.slider_float("field of view", v.fov_deg, 5, 60, "%.0f deg")
        moved |= c
        if imgui.button("Reset camera"):
            studio.view = View()
            moved = True
        imgui.same_line()
        imgui.text("drag: orbit, right-drag: pan, wheel: zoom")
        studio.dirty |= moved
    if changed:  # a slider moved: the sliders' controls are shown again
        studio.timeline_frame = -1
        studio.dirty = True
