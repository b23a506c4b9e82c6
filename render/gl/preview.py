"""The GL preview of the guide mesh: shaded with a shadow-mapped directional light, normals as
colours, a wireframe overlay and landmark points, drawn into an offscreen framebuffer."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import moderngl
import numpy as np

from render.camera import Camera, clipping_around, linear_depth_from_ndc
from render.gl.context import GLContext
from render.gl.shadow import ShadowMap, bounding_sphere, light_view_projection
from render.mesh import vertex_normals

PassName = Literal["shaded", "normals", "wireframe", "shadow"]
VERTEX_BYTES = 4 * 13
"""A vertex in the preview's buffer: position, normal, rest position, eyeball centre and flag (float32)."""


@dataclass(frozen=True)
class PreviewSettings:
    """What the preview draws and how it is lit."""

    pass_name: PassName = "shaded"
    """shaded: lit mesh; normals: world normals as colours; wireframe: shaded with edges;
    shadow: where the key light reaches (white) and where it is blocked (black)."""
    light_dir: tuple[float, float, float] = (0.45, 0.5, 0.75)
    """Direction from the head towards the key light, world space (normalised when used)."""
    shadows: bool = True
    """Cast shadows from a shadow map."""
    shadow_map_px: int = 2048
    """Shadow map resolution, pixels per side."""
    albedo: tuple[float, float, float] = (0.80, 0.62, 0.52)
    ambient: tuple[float, float, float] = (0.22, 0.22, 0.24)
    light_color: tuple[float, float, float] = (0.85, 0.85, 0.82)
    background: tuple[float, float, float] = (0.16, 0.17, 0.19)
    wireframe_overlay: bool = False
    """Edges over any pass (the `wireframe` pass turns this on)."""
    landmarks: bool = False
    """Draw the head model's landmarks as points."""
    samples: int = 4
    """Multisample anti-aliasing samples (1 = off)."""


@dataclass(frozen=True)
class MeshFrame:
    """One posed mesh to draw."""

    vertices: np.ndarray  # (V,3) metres
    triangles: np.ndarray  # (F,3)
    landmarks: np.ndarray | None = None  # (L,3)
    canonical: np.ndarray | None = None  # (V,3) the vertices at rest, where `eyes` are given
    eyes: np.ndarray | None = None
    """(V,4) each eyeball vertex's eyeball centre at rest and 1, 0 elsewhere (models/capture/scenes.py
    eye_attribute): the guide draws iris and pupil there. None: no eyes drawn."""


class PreviewRenderer:
    """Draws MeshFrames; owns its GL buffers, reuses them while the mesh size stays the same."""

    def __init__(self, gl: GLContext):
        self.gl = gl
        self.ctx = gl.ctx
        self._fbo: moderngl.Framebuffer | None = None
        self._resolve: moderngl.Framebuffer | None = None
        self._size: tuple[int, int, int] = (0, 0, 0)
        self._shadow = ShadowMap(gl)
        self._vbo: moderngl.Buffer | None = None
        self._ibo: moderngl.Buffer | None = None
        self._vbo_size = -1
        self.last_depth: np.ndarray | None = None

    def _framebuffer(self, w: int, h: int, samples: int) -> moderngl.Framebuffer:
        """The framebuffer to draw into; without multisampling it is the one read back."""
        samples = min(samples, self.ctx.max_samples) if samples > 1 else 0
        if self._size != (w, h, samples):
            for fb in {self._fbo, self._resolve} - {None}:
                fb.release()
            self._resolve = self.ctx.framebuffer(self.ctx.renderbuffer((w, h), 4),
                                                 self.ctx.depth_texture((w, h)))
            self._fbo = self._resolve if samples == 0 else self.ctx.framebuffer(
                self.ctx.renderbuffer((w, h), 4, samples=samples),
                self.ctx.depth_renderbuffer((w, h), samples=samples))
            self._size = (w, h, samples)
        return self._fbo

    def _upload(self, frame: MeshFrame) -> None:
        v = np.asarray(frame.vertices, np.float32)
        n = vertex_normals(v, frame.triangles)
        rest = v if frame.canonical is None or frame.eyes is None else frame.canonical
        eyes = np.zeros((len(v), 4), np.float32) if frame.eyes is None else frame.eyes
        data = np.concatenate([v, n, rest, eyes], 1).astype("f4").tobytes()
        if self._vbo is None or self._vbo_size != len(data):
            for b in (self._vbo, self._ibo):
                if b is not None:
                    b.release()
            self._vbo = self.ctx.buffer(data)
            self._vbo_size = len(data)
            self._ibo = self.ctx.buffer(np.asarray(frame.triangles, np.int32).tobytes())
        else:
            self._vbo.write(data)
            self._ibo.write(np.asarray(frame.triangles, np.int32).tobytes())

    def _vao(self, prog: moderngl.Program, with_normals: bool) -> moderngl.VertexArray:
        layout = (self._vbo, "3f 3f 3f 4f", "in_position", "in_normal", "in_canonical", "in_eye") if with_normals \
            else (self._vbo, f"3f {VERTEX_BYTES - 12}x", "in_position")
        return self.ctx.vertex_array(prog, [layout], index_buffer=self._ibo)

    def render(self, frame: MeshFrame, camera: Camera, settings: PreviewSettings = PreviewSettings(),
               read_depth: bool = False) -> np.ndarray:
        """RGB image (H,W,3) uint8, top row first. With read_depth, the camera depth (metres along the
        view axis, inf for background) is kept in `last_depth`."""
        camera = clipping_around(camera, frame.vertices, margin_m=0.05)  # as draw() clips: its depth's range
        with self.gl.current():
            result = self.draw(frame, camera, settings)
            w, h = camera.width_px, camera.height_px
            rgb = np.frombuffer(result.read(components=3, alignment=1), np.uint8).reshape(h, w, 3)
            if read_depth:
                depth01 = np.frombuffer(result.depth_attachment.read(alignment=1), np.float32).reshape(h, w)
                depth = np.where(depth01 < 1.0, linear_depth_from_ndc(depth01, camera.near_m, camera.far_m), np.inf)
                self.last_depth = depth[::-1].copy()
            return rgb[::-1].copy()  # GL rows run bottom-up

    def present(self, target: moderngl.Framebuffer) -> None:
        """Copy the last drawn image into another framebuffer of the same size (a window's screen)."""
        with self.gl.current():
            self.ctx.copy_framebuffer(target, self._resolve)

    def draw(self, frame: MeshFrame, camera: Camera, settings: PreviewSettings = PreviewSettings()
             ) -> moderngl.Framebuffer:
        """Draw without reading back; returns the single-sample framebuffer that holds the image."""
        camera = clipping_around(camera, frame.vertices, margin_m=0.05)  # wherever the controls put the head
        with self.gl.current():
            self._upload(frame)
            ctx = self.ctx
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)
            vp = (camera.projection @ camera.view).astype("f4")
            light_dir = np.asarray(settings.light_dir, np.float64)
            light_dir /= np.linalg.norm(light_dir)
            center, radius = bounding_sphere(frame.vertices)
            light_vp = light_view_projection(light_dir, center, radius).astype("f4")
            use_shadows = settings.shadows and settings.pass_name != "normals"
            if use_shadows:
                shadow_tex = self._shadow.draw(self._vbo, f"3f {VERTEX_BYTES - 12}x", self._ibo, light_vp,
                                               settings.shadow_map_px)
            fbo = self._framebuffer(camera.width_px, camera.height_px, settings.samples)
            fbo.use()
            fbo.clear(*settings.background, 1.0, depth=1.0)
            wire = settings.wireframe_overlay or settings.pass_name == "wireframe"
            prog = self.gl.program("surface", ("WIREFRAME",) if wire else ())
            prog["u_view_projection"].write(vp.T.tobytes())
            prog["u_light_view_projection"].write(light_vp.T.tobytes())
            prog["u_light_dir"].value = tuple(light_dir)
            prog["u_albedo"].value = settings.albedo
            prog["u_ambient"].value = settings.ambient
            prog["u_light_color"].value = settings.light_color
            prog["u_shadow_bias"].value = 1.0 / settings.shadow_map_px
            prog["u_normal_offset"].value = 1.5 * 2 * radius / settings.shadow_map_px  # 1.5 shadow-map texels
            prog["u_use_shadows"].value = int(use_shadows)
            prog["u_mode"].value = {"shadow": 1, "normals": 2}.get(settings.pass_name, 0)
            if wire:
                prog["u_wire_color"].value = (0.05, 0.05, 0.08, 0.55)
                prog["u_wire_width_px"].value = 1.0
            if use_shadows:
                shadow_tex.use(location=0)
            prog["u_shadow_map"].value = 0
            vao = self._vao(prog, True)
            vao.render(moderngl.TRIANGLES)
            vao.release()
            if settings.landmarks and frame.landmarks is not None and len(frame.landmarks):
                self._draw_points(frame.landmarks, vp, max(3.0, camera.height_px / 160))
            if fbo is not self._resolve:
                ctx.copy_framebuffer(self._resolve, fbo)
            return self._resolve

    def _draw_points(self, points: np.ndarray, vp: np.ndarray, size_px: float) -> None:
        """Landmarks as green points, drawn over the surface (not hidden by it)."""
        ctx = self.ctx
        flat = self.gl.program("flat")
        flat["u_view_projection"].write(vp.T.tobytes())
        ctx.enable(moderngl.PROGRAM_POINT_SIZE)
        ctx.disable(moderngl.DEPTH_TEST)
        flat["u_color"].value = (0.1, 1.0, 0.3, 1.0)
        flat["u_point_size_px"].value = size_px
        buf = ctx.buffer(np.asarray(points, "f4").tobytes())
        vao = ctx.vertex_array(flat, [(buf, "3f", "in_position")])
        vao.render(moderngl.POINTS)
        vao.release()
        buf.release()
        ctx.enable(moderngl.DEPTH_TEST)

    def release(self) -> None:
        with self.gl.current():
            for r in {self._fbo, self._resolve, self._vbo, self._ibo} - {None}:
                r.release()
            self._shadow.release()
