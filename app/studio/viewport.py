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
from app.studio.session import Session, views_warning
from models.avatars.card import AvatarCard
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


def buffer_label(name: str, avatar: AvatarCard | None) -> str:
    """An avatar that offers a render without cast shadows but not the light reaching the surface has no shadow
    factor: its render without them is the neutral head's counterfactual, labelled so."""
    offered = avatar.inspection_buffers() if avatar is not None else ()
    legacy = "rgb_no_shadows" in offered and "rgb_light" not in offered
    return LEGACY_LABELS.get(name, BUFFER_LABELS[name]) if legacy else BUFFER_LABELS[name]


def buffer_available(name: str, avatar: AvatarCard | None) -> bool:
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
        self.images: dict[str, tuple[int, int, int, int]] = {}
        """Each image drawn last frame (guide, neural, capture): x, y, width, height in the window (pixels)."""
        self.space: tuple[int, int, int, int] | None = None
        """The space the viewport gives its images (below its toolbar): x, y, width, height (pixels)."""
        self._guide_key: tuple = ()
        self.guide_draws = 0
        """How many times the guide was drawn (the report's: live driving holds it unless asked)."""

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
        """Draw the guide mesh into its texture, only when something it shows changed; while live, only where the
        guide follows live poses (Display.live_guide)."""
        sl, d, v = s.sliders, s.display, s.view
        if self.guide_paused(s):
            return
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
        self.guide_draws += 1

    def guide_paused(self, s: Session) -> bool:
        """Live driving with the guide held (Display.live_guide off): the guide drawn before stays."""
        return s.live.running and not s.display.live_guide and self.guide_tex is not None

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
        imgui.text(f"| {ctx.latency_from} to first pixels {ctx.latency_ms:.0f} ms")
        imgui.same_line()
    imgui.text("| rendering..." if worker.busy else "| at rest")
    if worker.error:
        imgui.text_colored(imgui.ImVec4(1, 0.4, 0.3, 1), worker.error)
    if s.avatar is None:
        imgui.text_disabled(s.absent("No avatar open: open one in the Avatar panel."))
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
    if warning := views_warning(s):
        imgui.text_colored(imgui.ImVec4(1.0, 0.75, 0.3, 1.0), warning)

    avail = imgui.get_content_region_avail()
    top_left = imgui.get_cursor_screen_pos()
    captured = vp.update_capture(s) and d.layout == "beside"  # the timeline's frame as the camera saw it
    n = (3 if captured else 2) if d.layout == "beside" else 1
    cols, size = grid_cell(n, avail.x, avail.y - 4)
    if size != d.shown_px:
        act(a.ShowAtSize(size))
    vp.draw_guide(s, size)
    vp.update_neural(r, d.buffer)
    vp.space = (int(top_left.x), int(top_left.y), int(avail.x), int(avail.y))
    cells = grid_cells(n, cols, size, avail.x, avail.y - 4)
    guide_ref = imgui.ImTextureRef(vp.guide_tex.glo)
    flip = (imgui.ImVec2(0, 1), imgui.ImVec2(1, 0))  # GL framebuffers run bottom-up
    neural = None if vp.neural_tex is None else imgui.ImTextureRef(vp.neural_tex.glo)
    if d.layout == "beside":
        shown = [("guide", guide_ref, vp.guide_tex.size, flip), ("neural", neural, _size(vp.neural_tex), ())]
        if captured:
            shown.append(("capture", imgui.ImTextureRef(vp.capture_tex.glo), vp.capture_tex.size, ()))
    else:
        shown = [("neural", neural, _size(vp.neural_tex), ())]
    vp.images = {}
    for (name, ref, tex_size, uv), (x, y) in zip(shown, cells, strict=True):
        ix, iy, w, h = fit(tex_size, size)
        at = (round(top_left.x + x + ix), round(top_left.y + y + iy))  # whole pixels: no blur from the placement
        imgui.set_cursor_screen_pos(imgui.ImVec2(*at))
        if ref is None:
            imgui.dummy(imgui.ImVec2(w, h))
        else:
            imgui.image(ref, imgui.ImVec2(w, h), *uv)
        vp.images[name] = (*at, w, h)
        if name == "guide" and vp.guide_paused(s):
            imgui.get_window_draw_list().add_text(imgui.ImVec2(at[0] + 6, at[1] + 4),
                                                  imgui.IM_COL32(230, 230, 230, 255),
                                                  "held while live (Live: guide follows)")
        if name == "capture":
            if imgui.is_item_hovered():
                imgui.set_tooltip(f"capture frame {s.timeline_frame}, as the camera saw it")
            continue
        if d.layout == "over":  # the guide over the render, at the slider's opacity
            lo = imgui.get_item_rect_min()
            hi = imgui.get_item_rect_max()
            imgui.get_window_draw_list().add_image(guide_ref, lo, hi, flip[0], flip[1],
                                                   imgui.IM_COL32(255, 255, 255, int(255 * d.overlay_alpha)))
        _mouse(act, size)
    vp.rect = bounds(list(vp.images.values()))


GAP_PX = 8
"""Between the viewport's images."""


def grid_cell(n: int, width: float, height: float, gap: float = GAP_PX) -> tuple[int, int]:
    """The columns and the square cell's side (pixels, at least 64) for n images in a grid that fits width x height
    with `gap` between them: of every column count, the one that shows them largest (a row in a wide viewport, a
    column in a tall one).

    >>> grid_cell(2, 690, 780)   # a row: (690 - 8) / 2 = 341 across; a column: (780 - 8) / 2 = 386 high
    (1, 386)
    >>> grid_cell(2, 1170, 970)  # a row: 581; a column: 481
    (2, 581)
    >>> grid_cell(3, 690, 780)   # a row: 224; two columns, two rows: min(341, 386) = 341; a column: 254
    (2, 341)
    """
    best = (1, 0)
    for cols in range(1, n + 1):
        rows = -(-n // cols)
        side = int(min((width - gap * (cols - 1)) / cols, (height - gap * (rows - 1)) / rows))
        if side > best[1]:
            best = (cols, side)
    return best[0], max(64, best[1])


def grid_cells(n: int, cols: int, side: int, width: float, height: float, gap: float = GAP_PX
               ) -> list[tuple[float, float]]:
    """The top-left corners of n square cells of `side` in `cols` columns, the grid centred in width x height and a
    last row of fewer cells centred under the others (pixels from the space's top-left).

    >>> grid_cells(3, 2, 100, 300, 250)  # grid 208 x 208: 46 px each side, 21 above and below
    [(46.0, 21.0), (154.0, 21.0), (100.0, 129.0)]
    """
    rows = -(-n // cols)
    x0 = max(0.0, (width - cols * side - gap * (cols - 1)) / 2)
    y0 = max(0.0, (height - rows * side - gap * (rows - 1)) / 2)
    cells = []
    for i in range(n):
        row, col = divmod(i, cols)
        in_row = min(cols, n - row * cols)
        shift = (cols - in_row) * (side + gap) / 2
        cells.append((x0 + shift + col * (side + gap), y0 + row * (side + gap)))
    return cells


def fit(image_size: tuple[int, int], side: int) -> tuple[int, int, int, int]:
    """An image of (width, height) pixels in a square cell of `side`, its aspect kept, centred: x, y, width, height.

    >>> fit((256, 256), 300), fit((320, 240), 300)
    ((0, 0, 300, 300), (0, 37, 300, 225))
    """
    w, h = image_size
    scale = side / max(w, h, 1)
    sw, sh = max(1, round(w * scale)), max(1, round(h * scale))
    return (side - sw) // 2, (side - sh) // 2, sw, sh


def bounds(boxes: list[tuple[int, int, int, int]]) -> tuple[int, int, int, int]:
    """The box (x, y, width, height) around boxes.

    >>> bounds([(10, 20, 100, 100), (118, 20, 100, 100), (64, 128, 100, 100)])
    (10, 20, 208, 208)
    """
    x0, y0 = min(b[0] for b in boxes), min(b[1] for b in boxes)
    return x0, y0, max(b[0] + b[2] for b in boxes) - x0, max(b[1] + b[3] for b in boxes) - y0


def _size(tex: moderngl.Texture | None) -> tuple[int, int]:
    return (1, 1) if tex is None else tex.size


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
