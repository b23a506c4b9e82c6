"""The Viewport panel: the GL guide mesh (shaded, normals, wireframe, landmarks) beside or under the neural
render, the neural buffer to show, mouse orbit (left drag), pan (right drag) and zoom (wheel), and each
pass's measured time."""

from __future__ import annotations

import moderngl
import numpy as np
from imgui_bundle import imgui
from PIL import Image

from app.display import INSPECT, PLAIN, buffer_image, guide_frame
from app.studio import actions as a
from app.studio.context import PanelContext
from app.studio.neural import Result
from app.studio.session import Session
from models.avatars.base import Avatar
from models.head.head import posed_mesh
from render.gl.context import GLContext
from render.gl.preview import PreviewRenderer, PreviewSettings

BUFFERS = ("rgb", "normals", "grad_normals", "depth", "opacity", "rgb_no_shadows", "rgb_light", "shadow_change",
           "shading")
BUFFER_LABELS = {"rgb": "RGB", "normals": "predicted normals", "grad_normals": "density-gradient normals",
                 "depth": "depth", "opacity": "opacity",
                 "rgb_no_shadows": "RGB without cast shadows",
                 "rgb_light": "light reaching the surface (cast shadows dark)",
                 "shadow_change": "cast shadows (render - render without them)",
                 "shading": "shading contribution (render - normals to viewer)"}
LEGACY_LABELS = {"rgb_no_shadows": "RGB, shadow inputs of the neutral head",
                 "shadow_change": "cast shadows (change from the neutral head's)"}
"""An avatar with shadows but no shadow factor (its capture recorded no key light, or it was trained before
the factor existed) has no render without cast shadows: its buffers are the counterfactual of the neutral
head's shadow inputs, and say so."""


def buffer_label(name: str, avatar: Avatar | None) -> str:
    """An avatar that offers a render without cast shadows but not the light reaching the surface has no shadow
    factor: its render without them is the neutral head's counterfactual, labelled so."""
    offered = avatar.inspection_buffers() if avatar is not None else ()
    legacy = "rgb_no_shadows" in offered and "rgb_light" not in offered
    return LEGACY_LABELS.get(name, BUFFER_LABELS[name]) if legacy else BUFFER_LABELS[name]


def buffer_available(name: str, avatar: Avatar | None) -> bool:
    """A buffer every render has, or one the avatar offers (a render makes it once it is shown)."""
    if name in INSPECT:
        return avatar is not None and INSPECT[name] in avatar.inspection_buffers()
    return name in PLAIN or (avatar is not None and name in avatar.default_buffers())


class Viewport:
    def __init__(self):
        self.gl: GLContext | None = None
        self.preview: PreviewRenderer | None = None
        self.guide_tex: moderngl.Texture | None = None
        self.neural_tex: moderngl.Texture | None = None
        self.neural_image: np.ndarray | None = None
        self.guide_image_size = (0, 0)
        self.shown = (-1, "", "")  # (request id, pass, buffer) on screen
        self.capture_tex: moderngl.Texture | None = None
        self._capture_key: tuple = ()
        self.rect: tuple[int, int, int, int] | None = None
        """Where the guide and the render were drawn in the window last frame: x, y, width, height (pixels)."""
        self._guide_key: tuple = ()

    def init(self, gl: GLContext) -> None:
        self.gl = gl
        self.preview = PreviewRenderer(gl)

    def texture(self, old: moderngl.Texture | None, size: tuple[int, int]) -> moderngl.Texture:
        if old is not None and old.size == size:
            return old
        if old is not None:
            old.release()
        return self.gl.ctx.texture(size, 3)

    def draw_guide(self, s: Session, size: int) -> None:
        """Draw the guide mesh into its texture, only when something it shows changed."""
        sl, d, v = s.sliders, s.display, s.view
        key = (size, d.guide_pass, d.wireframe, d.landmarks, s.timeline_frame,
               sl.expression.tobytes(), sl.head.tobytes(), sl.neck.tobytes(), sl.jaw_open_deg, sl.gaze_linked,
               sl.gaze_left.tobytes(), sl.gaze_right.tobytes(), v.yaw_deg, v.pitch_deg, v.zoom, v.fov_deg,
               v.pan.tobytes(), id(s.avatar))
        if key == self._guide_key and self.guide_tex is not None:
            return
        self._guide_key = key
        head = s.avatar.head_model
        verts, lmks = posed_mesh(s.avatar.head, s.controls())
        cam = s.render_camera(size)  # on the timeline, the capture's camera: the guide lines up with its image
        settings = PreviewSettings(pass_name=d.guide_pass, wireframe_overlay=d.wireframe, landmarks=d.landmarks,
                                   samples=1, shadow_map_px=1024)
        with self.gl.current():
            fb = self.preview.draw(guide_frame(head, verts, lmks if d.landmarks else None), cam, settings)
            self.guide_tex = self.texture(self.guide_tex, (size, size))
            self.gl.ctx.copy_framebuffer(self.guide_tex, fb)
            self.gl.ctx.detect_framebuffer(0).use()
        self.guide_image_size = (size, size)

    def update_capture(self, s: Session) -> bool:
        """On the timeline: the captured frame's image in its texture (read when the frame changes). False when
        no capture frame is shown."""
        cap, k = s.capture, s.timeline_frame
        if cap is None or not 0 <= k < len(cap.frames):
            return False
        key = (id(cap), k)
        if key != self._capture_key:
            try:
                with Image.open(cap.frames[k].image_path) as im:
                    img = np.ascontiguousarray(np.asarray(im.convert("RGB")))
            except OSError:
                return False
            with self.gl.current():
                self.capture_tex = self.texture(self.capture_tex, (img.shape[1], img.shape[0]))
                self.capture_tex.write(img.tobytes())
            self._capture_key = key
        return True

    def update_neural(self, r: Result | None, buffer: str) -> None:
        if r is None:
            return
        key = (r.request_id, r.pass_name, buffer)
        if key == self.shown:
            return
        name = buffer if INSPECT.get(buffer, buffer) in r.buffers else "rgb"
        img = buffer_image(r.buffers, name)
        with self.gl.current():
            self.neural_tex = self.texture(self.neural_tex, (img.shape[1], img.shape[0]))
            self.neural_tex.write(np.ascontiguousarray(img).tobytes())
        self.neural_image = img
        self.shown = key


def draw(ctx: PanelContext, vp: Viewport) -> None:
    s, act, worker = ctx.session, ctx.act, ctx.worker
    d = s.display
    r = worker.result
    imgui.text(f"interface {ctx.fps:.0f} fps")
    if imgui.is_item_hovered() and ctx.gui_ms is not None:
        imgui.set_tooltip(f"the window's own code: {ctx.gui_ms:.1f} ms a frame; the rest is drawing "
                          "and presenting (software GL here)")
    imgui.same_line()
    if r is not None:
        imgui.text(f"| neural {r.pass_name} pass {r.ms:.0f} ms")
        imgui.same_line()
    if ctx.latency_ms is not None:
        imgui.text(f"| slider to first pixels {ctx.latency_ms:.0f} ms")
        imgui.same_line()
    imgui.text("| rendering..." if worker.busy else "| at rest")
    if worker.error:
        imgui.text_colored(imgui.ImVec4(1, 0.4, 0.3, 1), worker.error)
    if s.avatar is None:
        imgui.text("No avatar open: open one in the Avatar panel.")
        return
    # What to show.
    available = [b for b in BUFFERS if buffer_available(b, s.avatar)]
    # Three short lines, so that nothing is clipped in the viewport a 1280 px window leaves (about 530 px).
    imgui.set_next_item_width(230)
    if imgui.begin_combo("buffer", buffer_label(d.buffer, s.avatar)):
        for b in available:
            if imgui.selectable(buffer_label(b, s.avatar), b == d.buffer)[0]:
                act(a.ShowBuffer(b))
        imgui.end_combo()
    imgui.same_line()
    imgui.set_next_item_width(90)
    passes = ("shaded", "normals", "shadow")
    changed, k = imgui.combo("guide", passes.index(d.guide_pass), list(passes))
    if changed:
        act(a.SetDisplay({"guide_pass": passes[k]}))
    for name in ("wireframe", "landmarks"):
        c, on = imgui.checkbox(name, getattr(d, name))
        if c:
            act(a.SetDisplay({name: on}))
        imgui.same_line()
    for layout, label in (("beside", "beside"), ("over", "over"), ("render", "render alone")):
        if imgui.radio_button(label, d.layout == layout):
            act(a.SetDisplay({"layout": layout}))
        imgui.same_line()
    imgui.new_line()
    if d.layout == "over":
        imgui.set_next_item_width(100)
        c, alpha = imgui.slider_float("guide opacity", d.overlay_alpha, 0.0, 1.0)
        if c:
            act(a.SetDisplay({"overlay_alpha": alpha}))
        imgui.same_line()
    imgui.text_disabled(f"render {d.neural_size} px shown at {d.shown_px} px"
                        + (" (linear filter)" if d.shown_px != d.neural_size else ""))
    relative_yaw = s.view.yaw_deg - float(s.sliders.head[0])  # the camera about the head, as the capture saw it
    if s.avatar.views_beyond(relative_yaw):
        lo, hi = s.avatar.view_range["yaw_deg"]
        imgui.text_colored(imgui.ImVec4(1.0, 0.75, 0.3, 1.0), f"beyond the captured views (yaw {lo:.0f} to {hi:.0f} "
                           "degrees): the avatar never saw this side of the head")

    avail = imgui.get_content_region_avail()
    captured = vp.update_capture(s) and d.layout == "beside"  # the timeline's frame as the camera saw it
    n = (3 if captured else 2) if d.layout == "beside" else 1
    size = int(max(64, min((avail.x - 8 * (n - 1)) / n, avail.y - 4)))
    if size != d.shown_px:
        act(a.ShowAtSize(size))
    vp.draw_guide(s, size)
    vp.update_neural(r, d.buffer)
    origin = imgui.get_cursor_screen_pos()
    guide_ref = imgui.ImTextureRef(vp.guide_tex.glo)
    flip = (imgui.ImVec2(0, 1), imgui.ImVec2(1, 0))  # GL framebuffers run bottom-up
    if d.layout == "beside":
        imgui.image(guide_ref, imgui.ImVec2(size, size), *flip)
        _mouse(act, size)
        imgui.same_line()
        if vp.neural_tex is not None:
            imgui.image(imgui.ImTextureRef(vp.neural_tex.glo), imgui.ImVec2(size, size))
            _mouse(act, size)
        if captured:
            imgui.same_line()
            imgui.image(imgui.ImTextureRef(vp.capture_tex.glo), imgui.ImVec2(size, size))
            if imgui.is_item_hovered():
                imgui.set_tooltip(f"capture frame {s.timeline_frame}, as the camera saw it")
    elif d.layout == "render":
        if vp.neural_tex is not None:
            imgui.image(imgui.ImTextureRef(vp.neural_tex.glo), imgui.ImVec2(size, size))
        else:
            imgui.dummy(imgui.ImVec2(size, size))
        _mouse(act, size)
    else:
        if vp.neural_tex is not None:
            imgui.image(imgui.ImTextureRef(vp.neural_tex.glo), imgui.ImVec2(size, size))
        draw_list = imgui.get_window_draw_list()
        alpha = int(255 * d.overlay_alpha)
        draw_list.add_image(guide_ref, origin, imgui.ImVec2(origin.x + size, origin.y + size), flip[0], flip[1],
                            imgui.IM_COL32(255, 255, 255, alpha))
        if vp.neural_tex is None:
            imgui.dummy(imgui.ImVec2(size, size))
        _mouse(act, size)
    end = imgui.get_item_rect_max()
    vp.rect = (int(origin.x), int(origin.y), int(end.x - origin.x), int(end.y - origin.y))


def _mouse(act, size: int) -> None:
    """Orbit, pan and zoom when the mouse is over the last drawn image."""
    if not imgui.is_item_hovered():
        return
    io = imgui.get_io()
    d = io.mouse_delta
    if imgui.is_mouse_dragging(imgui.MouseButton_.left) and (d.x or d.y):
        act(a.Orbit(d.x, d.y))
    elif imgui.is_mouse_dragging(imgui.MouseButton_.right) and (d.x or d.y):
        act(a.Pan(d.x, d.y, size))
    if io.mouse_wheel:
        act(a.Zoom(io.mouse_wheel))
