"""The Controls panel: every expression component (named where the head model names them; a filter box),
head pose, neck, jaw, gaze (linked or each eye), the camera orbit, resets (all, and per group: brows, eyes,
mouth..., head, neck, jaw, gaze, camera), undo and redo (Ctrl+Z, Ctrl+Shift+Z or Ctrl+Y), named poses of the
avatar, and a timeline over the capture's frames that loads a frame's controls and shows its image beside the
render."""

from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

from app.animation import SLIDER_RANGES
from app.studio import actions as a
from app.studio.context import PanelContext
from app.studio.session import expression_groups


class PanelState:
    filter_text = ""
    pose_name = ""


def draw_history(ctx: PanelContext) -> None:
    """Undo and redo, as buttons and keys (Ctrl+Z; Ctrl+Shift+Z or Ctrl+Y), with how many steps each has."""
    h, act = ctx.session.history, ctx.act
    ctrl, shift = imgui.Key.mod_ctrl, imgui.Key.mod_shift
    keys = not imgui.get_io().want_text_input  # a text field being typed in has its own undo
    if imgui.button(f"Undo ({len(h.undo)})") or (keys and imgui.is_key_chord_pressed(ctrl | imgui.Key.z)):
        act(a.Undo())
    imgui.same_line()
    if imgui.button(f"Redo ({len(h.redo)})") or (keys and (imgui.is_key_chord_pressed(ctrl | shift | imgui.Key.z)
                                                          or imgui.is_key_chord_pressed(ctrl | imgui.Key.y))):
        act(a.Undo(forward=True))


def draw_poses(ctx: PanelContext) -> None:
    """Named poses of this avatar: save the sliders under a name, recall or delete one."""
    s, act = ctx.session, ctx.act
    imgui.set_next_item_width(140)
    _, PanelState.pose_name = imgui.input_text("##pose_name", PanelState.pose_name)
    imgui.same_line()
    if imgui.button("Save pose"):
        act(a.SavePose(PanelState.pose_name))
    if imgui.is_item_hovered():
        imgui.set_tooltip("the face's sliders (expression, head, neck, jaw, gaze) under this name, for this avatar; "
                          "the camera is not part of a pose")
    for name in sorted(s.poses):
        imgui.push_id(f"pose_{name}")
        if imgui.small_button(name):
            act(a.RecallPose(name))
        imgui.same_line()
        if imgui.small_button("x"):
            act(a.DeletePose(name))
        imgui.pop_id()
    if not s.poses:
        imgui.text_disabled("no poses saved for this avatar")


def _angles(label: str, values: np.ndarray, names: tuple[str, ...], limit: float) -> tuple[float, ...] | None:
    """Sliders for a set of angles (degrees); the new values where one moved."""
    new = [float(v) for v in values]
    changed = False
    for i, n in enumerate(names):
        c, new[i] = imgui.slider_float(f"{n}##{label}", new[i], -limit, limit, "%.1f deg")
        changed |= c
    return tuple(new) if changed else None


def draw(ctx: PanelContext) -> None:
    s, act = ctx.session, ctx.act
    if s.avatar is None:
        imgui.text_disabled(s.absent("Open an avatar to drive it."))
        return
    sl = s.sliders
    head = s.avatar.head_model
    if s.capture is not None and s.capture.frames:
        n = len(s.capture.frames)
        imgui.text("Timeline (capture frames; -1: the sliders)")
        c, k = imgui.slider_int("frame", s.timeline_frame, -1, n - 1)
        if c:
            act(a.ShowFrame(k))
        if s.timeline_frame >= 0 and imgui.button("Copy this frame to the sliders"):
            act(a.CopyFrameToSliders())
    elif s.files.capture_note:  # a note, not an error: an avatar travels without its capture
        imgui.push_text_wrap_pos(0)
        imgui.text_disabled(s.files.capture_note)
        imgui.pop_text_wrap_pos()
    if s.timeline_frame >= 0:
        imgui.text_wrapped("Showing a capture frame: the sliders below take over when you move them.")
    draw_history(ctx)
    if imgui.collapsing_header("Poses"):
        draw_poses(ctx)

    if imgui.collapsing_header("Expression", imgui.TreeNodeFlags_.default_open):
        if imgui.button("Reset expression"):
            act(a.ResetExpression())
        imgui.same_line()
        imgui.set_next_item_width(140)
        _, PanelState.filter_text = imgui.input_text("filter", PanelState.filter_text)
        groups = expression_groups(head)
        if len(groups) > 1:
            imgui.text("reset:")
            for group in groups:
                imgui.same_line()
                if imgui.small_button(group):
                    act(a.ResetGroup(f"expression:{group}"))
        needle = PanelState.filter_text.lower()
        names = [head.expr_names[i] if i < len(head.expr_names) else f"expression {i}"
                 for i in range(head.num_expression)]
        # the sliders leave room for the longest name beside them (at 1440x900 browInnerUp_L showed as browInnerUp_)
        label_px = max((imgui.calc_text_size(n).x for n in names), default=0.0) + imgui.get_style().item_inner_spacing.x
        imgui.push_item_width(max(80.0, imgui.get_content_region_avail().x - label_px))
        for i, name in enumerate(names):
            if needle and needle not in name.lower():
                continue
            c, v = imgui.slider_float(name, float(sl.expression[i]), *SLIDER_RANGES["expression"], "%.2f")
            if c:
                act(a.SetExpression(i, v))
        imgui.pop_item_width()
    if imgui.collapsing_header("Head and neck", imgui.TreeNodeFlags_.default_open):
        if imgui.button("Reset pose"):
            act(a.ResetPose())
        imgui.same_line()
        if imgui.small_button("head##reset"):
            act(a.ResetGroup("head"))
        if "neck" in head.joint_names:
            imgui.same_line()
            if imgui.small_button("neck##reset"):
                act(a.ResetGroup("neck"))
        if (moved := _angles("head", sl.head, ("head yaw", "head pitch", "head roll"),
                            SLIDER_RANGES["head"][1])) is not None:
            act(a.SetAngles("head", moved))
        if "neck" in head.joint_names and (
                moved := _angles("neck", sl.neck, ("neck yaw", "neck pitch", "neck roll"),
                SLIDER_RANGES["neck"][1])) is not None:
            act(a.SetAngles("neck", moved))
    if "jaw" in head.joint_names and imgui.collapsing_header("Jaw", imgui.TreeNodeFlags_.default_open):
        c, v = imgui.slider_float("jaw open", sl.jaw_open_deg, *SLIDER_RANGES["jaw.open"], "%.1f deg")
        if c:
            act(a.SetJaw(v))
        if imgui.small_button("Reset jaw"):
            act(a.ResetGroup("jaw"))
    if {"eye_l", "eye_r"} <= set(head.joint_names) and imgui.collapsing_header("Gaze"):
        c, linked = imgui.checkbox("both eyes together", sl.gaze_linked)
        if c:
            act(a.LinkGaze(linked))
        names = ("gaze yaw", "gaze pitch") if sl.gaze_linked else ("left yaw", "left pitch")
        if (moved := _angles("gl", sl.gaze_left, names, SLIDER_RANGES["gaze"][1])) is not None:
            act(a.SetAngles("gaze_left", moved))
        if not sl.gaze_linked and (moved := _angles("gr", sl.gaze_right, ("right yaw", "right pitch"),
                                                          SLIDER_RANGES["gaze"][1])) is not None:
            act(a.SetAngles("gaze_right", moved))
        if imgui.button("Reset gaze"):
            act(a.ResetGaze())
    if imgui.collapsing_header("Camera", imgui.TreeNodeFlags_.default_open):
        v = s.view
        c, yaw = imgui.slider_float("orbit yaw", v.yaw_deg, -180, 180, "%.0f deg")
        if c:
            act(a.SetView(yaw_deg=yaw))
        c, pitch = imgui.slider_float("orbit pitch", v.pitch_deg, -85, 85, "%.0f deg")
        if c:
            act(a.SetView(pitch_deg=pitch))
        c, zoom = imgui.slider_float("zoom", v.zoom, 0.25, 8.0, "%.2fx", imgui.SliderFlags_.logarithmic)
        if c:
            act(a.SetView(zoom=zoom))
        c, fov = imgui.slider_float("field of view", v.fov_deg, 5, 60, "%.0f deg")
        if c:
            act(a.SetView(fov_deg=fov))
        if imgui.button("Reset camera"):
            act(a.ResetView())
        imgui.same_line()
        imgui.text("drag: orbit, right-drag: pan, wheel: zoom")
