"""Synthetic capture frames: a posed mesh under a lighting scene, with ground-truth buffers, supersampled
and box-filtered so that images are anti-aliased and masks carry coverage."""

from __future__ import annotations

from dataclasses import dataclass, field

import moderngl
import numpy as np

from render.camera import Camera
from render.gl.context import GLContext
from render.gl.shadow import ShadowMap, bounding_sphere, light_view_projection
from render.mesh import vertex_normals


@dataclass(frozen=True)
class CaptureLighting:
    """The light of a scene. Colours are linear RGB."""

    sh: np.ndarray  # (9,3) irradiance SH coefficients
    light_dir: np.ndarray  # (3,) towards the key light, world
    light_color: np.ndarray  # (3,)
    diffuse: bool
    specular: bool
    shadows: bool
    shininess: float = 40.0
    shadow_map_px: int = 2048


@dataclass(frozen=True)
class Appearance:
    """The solid albedo texture and specular map: colours, and face regions in canonical metres."""

    skin_color: np.ndarray  # (3,)
    lip_color: np.ndarray
    brow_color: np.ndarray
    iris_color: np.ndarray
    lip_center: np.ndarray  # (3,)
    lip_radii: np.ndarray  # (2,)
    brow_centers: np.ndarray  # (2,3)
    brow_radii: np.ndarray  # (2,)
    nose_top: np.ndarray  # (3,)
    nose_tip: np.ndarray  # (3,)
    forehead_center: np.ndarray  # (3,)
    forehead_radii: np.ndarray  # (3,)
    specular_range: tuple[float, float] = (0.04, 0.5)
    seed: float = 0.0
    hair_color: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,)
    cheek_centers: np.ndarray = field(default_factory=lambda: np.full((2, 3), -10.0))  # (2,3) blush centres
    blush: float = 0.0  # 0..1


@dataclass(frozen=True)
class CaptureMesh:
    vertices: np.ndarray  # (V,3) posed, world metres
    triangles: np.ndarray  # (F,3)
    canonical: np.ndarray  # (V,3) neutral with identity, metres
    material: np.ndarray  # (V,4) w: material id (0 skin, 1 eye, 2 hair, 3 teeth, 4 lashes); xyz its coordinates
    tangent: np.ndarray | None = None  # (V,3) posed direction of the hair's strands; None: no hair


@dataclass(frozen=True)
class CaptureBuffers:
    """One frame, H x W, rows top first. Colours linear; background not composited."""

    color: np.ndarray  # (H,W,3) premultiplied by coverage
    coverage: np.ndarray  # (H,W) in [0,1]
    normal: np.ndarray  # (H,W,3) unit where coverage > 0, else 0
    albedo: np.ndarray  # (H,W,3)
    specular: np.ndarray  # (H,W) specular strength map
    visibility: np.ndarray  # (H,W) key light reaching the surface: 1 lit, 0 blocked
    n_dot_l: np.ndarray  # (H,W)
    depth: np.ndarray  # (H,W) metres along the view axis, inf for background


def _box(a: np.ndarray, s: int) -> np.ndarray:
    """Mean over s x s blocks of the first two axes."""
    h, w = a.shape[0] // s, a.shape[1] // s
    return a.reshape(h, s, w, s, *a.shape[2:]).mean(axis=(1, 3))


class CaptureRenderer:
    """Draws CaptureMeshes into float targets at `supersample` times the camera's resolution."""

    def __init__(self, gl: GLContext, supersample: int = 2):
        self.gl = gl
        self.supersample = supersample
        self._shadow = ShadowMap(gl)
        self._fbo: moderngl.Framebuffer | None = None
        self._targets: list[moderngl.Texture] = []
        self._size = (0, 0)

    def _framebuffer(self, w: int, h: int) -> moderngl.Framebuffer:
        if self._size != (w, h):
            self._release_targets()
            ctx = self.gl.ctx
            self._targets = [ctx.texture((w, h), 4, dtype="f4") for _ in range(4)]
            self._fbo = ctx.framebuffer(self._targets, ctx.depth_renderbuffer((w, h)))
            self._size = (w, h)
        return self._fbo

    def render(self, mesh: CaptureMesh, camera: Camera, lighting: CaptureLighting, look: Appearance
               ) -> CaptureBuffers:
        with self.gl.current():
            ctx = self.gl.ctx
            s = self.supersample
            W, H = camera.width_px * s, camera.height_px * s
            n = vertex_normals(mesh.vertices, mesh.triangles)
            tangent = np.zeros_like(mesh.vertices) if mesh.tangent is None else mesh.tangent
            data = np.concatenate([mesh.vertices, n, mesh.canonical, mesh.material, tangent], 1).astype("f4")
            vbo = ctx.buffer(data.tobytes())
            ibo = ctx.buffer(np.asarray(mesh.triangles, "i4").tobytes())
            light_dir = np.asarray(lighting.light_dir, np.float64) / np.linalg.norm(lighting.light_dir)
            center, radius = bounding_sphere(mesh.vertices)
            light_vp = light_view_projection(light_dir, center, radius).astype("f4")
            if lighting.shadows:
                self._shadow.draw(vbo, "3f 52x", ibo, light_vp, lighting.shadow_map_px)  # 16 floats a vertex
            fbo = self._framebuffer(W, H)
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
            prog = self.gl.program("capture")
            vp = (camera.projection @ camera.view).astype("f4")
            prog["u_view_projection"].write(vp.T.tobytes())
            prog["u_view"].write(camera.view.astype("f4").T.tobytes())
            prog["u_light_view_projection"].write(light_vp.T.tobytes())
            prog["u_normal_offset"].value = 1.5 * 2 * radius / lighting.shadow_map_px
            prog["u_shadow_bias"].value = 1.0 / lighting.shadow_map_px
            prog["u_camera_position"].value = tuple(camera.position)
            prog["u_sh"].write(np.asarray(lighting.sh, "f4").tobytes())
            prog["u_light_dir"].value = tuple(light_dir)
            prog["u_light_color"].value = tuple(np.asarray(lighting.light_color, float))
            prog["u_use_diffuse"].value = int(lighting.diffuse)
            prog["u_use_specular"].value = int(lighting.specular)
            prog["u_use_shadows"].value = int(lighting.shadows)
            prog["u_shininess"].value = float(lighting.shininess)
            if lighting.shadows:
                self._shadow.texture.use(location=0)
            prog["u_shadow_map"].value = 0
            for name in ("skin_color", "lip_color", "brow_color", "iris_color", "hair_color", "lip_center", "lip_radii",
                         "brow_radii", "nose_top", "nose_tip", "forehead_center", "forehead_radii", "specular_range"):
                prog[f"u_{name}"].value = tuple(float(x) for x in np.ravel(getattr(look, name)))
            prog["u_brow_center"].write(np.asarray(look.brow_centers, "f4").tobytes())
            prog["u_cheek_center"].write(np.asarray(look.cheek_centers, "f4").tobytes())
            prog["u_blush"].value = float(look.blush)
            prog["u_seed"].value = float(look.seed)
            vao = ctx.vertex_array(prog, [(vbo, "3f 3f 3f 4f 3f", "in_position", "in_normal", "in_canonical",
                                           "in_material", "in_tangent")],
                                   index_buffer=ibo)
            vao.render(moderngl.TRIANGLES)
            vao.release()
            vbo.release()
            ibo.release()
            maps = [np.frombuffer(t.read(), np.float32).reshape(H, W, 4)[::-1] for t in self._targets]
            return self._downsample(*maps)

    def _downsample(self, color: np.ndarray, normal: np.ndarray, albedo: np.ndarray, light: np.ndarray
                    ) -> CaptureBuffers:
        s = self.supersample
        alpha = color[..., 3]
        coverage = _box(alpha, s)
        covered = coverage > 0
        weight = np.where(covered, coverage, 1.0)

        def mean_over_covered(a: np.ndarray) -> np.ndarray:
            return _box(a * (alpha[..., None] if a.ndim == 3 else alpha), s) / (
                weight[..., None] if a.ndim == 3 else weight)

        n = _box(normal[..., :3], s)
        length = np.linalg.norm(n, axis=2, keepdims=True)
        n = np.where(length > 1e-8, n / np.maximum(length, 1e-8), 0.0)
        depth = mean_over_covered(light[..., 2])
        return CaptureBuffers(
            color=_box(color[..., :3], s),
            coverage=coverage,
            normal=n.astype(np.float32),
            albedo=mean_over_covered(albedo[..., :3]),
            specular=mean_over_covered(albedo[..., 3]),
            visibility=np.where(covered, mean_over_covered(light[..., 0]), 1.0),
            n_dot_l=mean_over_covered(light[..., 1]),
            depth=np.where(covered, depth, np.inf),
        )

    def _release_targets(self) -> None:
        if self._fbo is not None:
            self._fbo.release()
        for t in self._targets:
            t.release()
        self._targets, self._fbo = [], None

    def release(self) -> None:
        with self.gl.current():
            self._release_targets()
            self._shadow.release()
