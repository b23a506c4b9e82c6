"""Per-pixel geometry of a mesh seen by a camera, in milliseconds on llvmpipe: which triangle each pixel
sees, where along its ray, and the barycentric coordinates of that point (DESIGN 5: a sampler starts here)."""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from render.camera import Camera
from render.gl.context import GLContext


@dataclass(frozen=True)
class Raster:
    """H x W, rows top first."""

    triangle: np.ndarray  # (H,W) int, -1 where the pixel sees no surface
    depth: np.ndarray  # (H,W) metres along the view axis, inf where no surface
    bary: np.ndarray  # (H,W,3) barycentric coordinates of the visible point (0 where no surface)

    @property
    def hit(self) -> np.ndarray:
        return self.triangle >= 0


def pixel_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """World origin (3,) and unit directions (H,W,3) through pixel centres, rows top first."""
    h, w = camera.height_px, camera.width_px
    t = np.tan(np.radians(camera.fov_y_deg) / 2)
    j, i = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    d_cam = np.stack([(2 * j / w - 1) * t * w / h, (1 - 2 * i / h) * t, -np.ones_like(j)], -1)
    c2w = np.linalg.inv(camera.view)
    d = d_cam @ c2w[:3, :3].T
    return c2w[:3, 3], d / np.linalg.norm(d, axis=-1, keepdims=True)


def surface_distance(raster: Raster, cos_view: np.ndarray) -> np.ndarray:
    """(H,W) distance along each pixel's unit ray to the visible surface, inf where it misses: the view
    depth over the cosine between the ray and the view axis (cos_view, (H,W))."""
    return np.where(raster.hit, raster.depth / np.maximum(cos_view, 1e-6), np.inf).astype(np.float32)


def ray_triangle_barycentric(origin: np.ndarray, dirs: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (N,3) where rays (origin, (N,3) dirs) meet the planes of (N,3,3) triangles
    (Moller-Trumbore without the inside test: the rasterizer already chose the triangle)."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(dirs, e2)
    det = np.einsum("ij,ij->i", e1, p)
    det = np.where(np.abs(det) < 1e-20, 1e-20, det)
    s = origin - tri[:, 0]
    u = np.einsum("ij,ij->i", s, p) / det
    q = np.cross(s, e1)
    v = np.einsum("ij,ij->i", dirs, q) / det
    return np.clip(np.stack([1 - u - v, u, v], -1), 0.0, 1.0)


class Rasterizer:
    """Draws triangle ids and depth into an integer and a float target; reuses them per size."""

    def __init__(self, gl: GLContext):
        self.gl = gl
        self._fbo: moderngl.Framebuffer | None = None
        self._size = (0, 0)

    def rasterize(self, vertices: np.ndarray, triangles: np.ndarray, camera: Camera) -> Raster:
        tri, depth = self._draw(vertices, triangles, camera.view, camera.projection, camera.width_px,
                                camera.height_px)
        hit = tri >= 0
        bary = np.zeros((*tri.shape, 3), np.float32)
        if hit.any():
            origin, dirs = pixel_rays(camera)
            corners = np.asarray(vertices, np.float64)[np.asarray(triangles)[tri[hit]]]
            bary[hit] = ray_triangle_barycentric(origin, dirs[hit], corners)
        return Raster(tri, np.where(hit, depth, np.inf), bary)

    def depth_map(self, vertices: np.ndarray, triangles: np.ndarray, view: np.ndarray, projection: np.ndarray,
                  px: int) -> np.ndarray:
        """(px,px) distance along the view axis to the nearest surface, inf where there is none, rows top
        first, for any view and projection (an orthographic one from a light gives a shadow map)."""
        tri, depth = self._draw(vertices, triangles, view, projection, px, px)
        return np.where(tri >= 0, depth, np.inf).astype(np.float32)

    def _draw(self, vertices: np.ndarray, triangles: np.ndarray, view: np.ndarray, projection: np.ndarray, w: int,
              h: int) -> tuple[np.ndarray, np.ndarray]:
        """Triangle ids (-1 where none) and view depth, (h,w) each, rows top first."""
        with self.gl.current():
            ctx = self.gl.ctx
            if self._size != (w, h):
                self.release()
                self._depth = ctx.texture((w, h), 1, dtype="f4")
                self._tri = ctx.texture((w, h), 1, dtype="i4")
                self._fbo = ctx.framebuffer([self._depth, self._tri], ctx.depth_renderbuffer((w, h)))
                self._size = (w, h)
            vbo = ctx.buffer(np.asarray(vertices, "f4").tobytes())
            ibo = ctx.buffer(np.asarray(triangles, "i4").tobytes())
            prog = self.gl.program("raster")
            prog["u_view_projection"].write((projection @ view).astype("f4").T.tobytes())
            prog["u_view"].write(np.asarray(view).astype("f4").T.tobytes())
            vao = ctx.vertex_array(prog, [(vbo, "3f", "in_position")], index_buffer=ibo)
            self._fbo.use()
            self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
            vao.render(moderngl.TRIANGLES)
            vao.release()
            vbo.release()
            ibo.release()
            tri = np.frombuffer(self._tri.read(), np.int32).reshape(h, w)[::-1] - 1
            depth = np.frombuffer(self._depth.read(), np.float32).reshape(h, w)[::-1]
            return tri.copy(), depth.copy()

    def release(self) -> None:
        with self.gl.current():
            if self._fbo is not None:
                self._fbo.release()
                self._depth.release()
                self._tri.release()
            self._fbo = None
            self._size = (0, 0)
