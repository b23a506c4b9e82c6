"""A shadow map for one directional light: an orthographic depth render from the light."""

from __future__ import annotations

import moderngl
import numpy as np
import torch

from render.camera import look_at, orthographic
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.shadow_map import LIGHT_MAP_PX, LightDepthMap


def light_camera(light_dir: np.ndarray, center: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """View and orthographic projection of a light camera that sees a sphere of `radius_m` about `center` from
    `light_dir`."""
    d = np.asarray(light_dir, np.float64) / np.linalg.norm(light_dir)
    eye = center + d * (3 * radius_m)
    return look_at(eye, center), orthographic(radius_m, radius_m, radius_m, 5 * radius_m)


def light_view_projection(light_dir: np.ndarray, center: np.ndarray, radius_m: float) -> np.ndarray:
    """Orthographic light camera that sees a sphere of `radius_m` about `center` from `light_dir`."""
    view, projection = light_camera(light_dir, center, radius_m)
    return projection @ view


def bounding_sphere(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre of the bounding box and a radius that holds every vertex (with 5% to spare)."""
    v = np.asarray(vertices, np.float64)
    center = 0.5 * (v.min(0) + v.max(0))
    return center, float(np.linalg.norm(v - center, axis=1).max()) * 1.05 + 1e-6


class ShadowMap:
    """Depth texture (compare mode, bilinear PCF) drawn from the light; reused while its size stays."""

    def __init__(self, gl: GLContext):
        self.gl = gl
        self.texture: moderngl.Texture | None = None
        self._fbo: moderngl.Framebuffer | None = None

    def draw(self, vbo: moderngl.Buffer, position_format: str, ibo: moderngl.Buffer, light_vp: np.ndarray,
             px: int) -> moderngl.Texture:
        """Render the triangles' depth from the light. position_format: the vertex layout with only
        in_position read, e.g. '3f 12x'."""
        ctx = self.gl.ctx
        if self.texture is None or self.texture.size != (px, px):
            self.release()
            self.texture = ctx.depth_texture((px, px))
            self.texture.compare_func = "<="
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = False
            self._fbo = ctx.framebuffer(depth_attachment=self.texture)
        self._fbo.use()
        self._fbo.clear(depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        prog = self.gl.program("depth")
        prog["u_view_projection"].write(np.asarray(light_vp, "f4").T.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, position_format, "in_position")], index_buffer=ibo)
        vao.render(moderngl.TRIANGLES)
        vao.release()
        return self.texture

    def release(self) -> None:
        for r in (self._fbo, self.texture):
            if r is not None:
                r.release()
        self._fbo = self.texture = None


def draw_light_depth(rasterizer: Rasterizer, vertices: np.ndarray, triangles: np.ndarray,
                     light_dir: np.ndarray | tuple, px: int = LIGHT_MAP_PX) -> LightDepthMap:
    """The depth map of a posed mesh (V,3) seen from a directional light (towards the light, world), as arrays
    for render/shadow_map.py's lookup."""
    view, projection = light_camera(light_dir, *bounding_sphere(vertices))
    depth = rasterizer.depth_map(vertices, triangles, view, projection, px)
    t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)
    return LightDepthMap(t(view), t(projection), t(depth))
