"""A colour texture baked from an avatar: renders of it at rest from cameras round the head, each texel taking the
colour of the camera that sees its point most squarely and unoccluded, the texels no camera saw filled from around.

The avatar is asked only through its interface (render_image, frame_geometry, at_rest, rest_vertices,
turntable_sweep_deg, views_beyond, view_range); the guide mesh is rasterized by the GL rasterizer for each camera's
depth, which says where a texel's point is hidden.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from models.avatars.base import Avatar
from models.avatars.rendering import RenderOptions, render_image
from models.export.chart import Chart
from models.head.controls import Controls
from render.camera import Camera, project
from render.fill import push_pull
from render.gl.raster import Rasterizer
from render.mesh import vertex_normals
from render.rays import Raster

MIN_COS = 0.25
"""A camera sees a texel's point only within 75 degrees of its normal (beyond, a pixel smears many texels)."""
MIN_OPACITY = 0.5
"""...and where the render is more the avatar's than the background's (bilinear opacity at the point's pixel; the
avatar's colour there is the render's with the background taken out: (rgb - (1 - opacity) background) / opacity)."""
DEPTH_SLACK_M = 0.002
"""How far behind the nearest surface (along the view axis) a point still counts as seen, besides the depth a
pixel spans on a slanted surface: the guide mesh's rasterized depth is the pixel centre's, the point's its own."""
FEATHER_COS = 0.03
"""Where two cameras see a point almost as squarely, their colours blend (weights exp((cos - cos_best) / 0.03): a
camera 0.03 less square counts 0.37 of the best, 0.1 less 0.04), so that a texture does not step where the best
camera changes and the avatar's view-dependent colour (a highlight) differs between the two."""
REACH_PX = 0.75
"""Texels whose centre lies within this distance (texels) of a triangle take a point on it (clamped), so that a
viewer's bilinear lookup along a chart's edge meets baked texels, not fill."""


@dataclass(frozen=True, eq=False)
class TexelSurface:
    """Where each texel lies on the mesh: a triangle and barycentric weights (triangle -1: none)."""

    triangle: np.ndarray  # (H,W) int64, -1 where no triangle
    bary: np.ndarray  # (H,W,3) float32, 0 where no triangle

    @property
    def covered(self) -> np.ndarray:
        return self.triangle >= 0


@dataclass(frozen=True, eq=False)
class BakedTexture:
    image: np.ndarray  # (H,W,3) uint8, rows top first (glTF's v down)
    covered: np.ndarray  # (H,W) bool: texels on the chart's triangles (the rest lie between them)
    seen: np.ndarray  # (H,W) bool: texels a camera saw (the rest are filled from around)
    view: np.ndarray  # (H,W) int: the view each seen texel took its colour from, -1 elsewhere
    views: list[tuple[float, float]]  # (yaw_deg, pitch_deg) of each camera
    render_px: int  # the renders' width and height

    @property
    def seen_share(self) -> float:
        """The share of the chart's texels that a camera saw."""
        return float(self.seen.sum() / max(self.covered.sum(), 1))


def texel_surface(uv: np.ndarray, triangles: np.ndarray, size: int, reach_px: float = REACH_PX,
                  chunk_pairs: int = 1 << 20) -> TexelSurface:
    """The triangle under each texel's centre and its barycentric weights there (clamped onto the triangle for
    centres up to reach_px outside it), on a size x size texture. uv: (N,2) in [0,1], glTF's (texel (row r,
    column c) has its centre at ((c + 0.5) / size, (r + 0.5) / size)); triangles: (F,3).

    Where several triangles claim a texel, one whose uv winding agrees with most triangles' wins over one turned
    over (a triangle across a chart's wrap-around seam spans the chart backwards), then the one the centre lies
    deepest inside (its least distance to an edge, in texels).

    >>> s = texel_surface(np.array([[0, 0], [1, 0], [0, 1]], np.float32), np.array([[0, 1, 2]]), 2, reach_px=0)
    >>> s.triangle.tolist(), s.bary[0, 0].tolist()  # centre (0.5, 0.5) texels = uv (1/4, 1/4): 1/2 v0 + 1/4 v1 + 1/4 v2
    ([[0, 0], [0, -1]], [0.5, 0.25, 0.25])
    """
    p = np.asarray(uv, np.float64)[np.asarray(triangles)] * size  # (F,3,2) texel units, x right, y down
    signed = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                    - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    usable = np.abs(signed) > 1e-12
    majority = np.sign(np.sign(signed[usable]).sum()) or 1.0
    turned = np.sign(signed) != majority
    lo = np.clip(np.floor(p.min(1) - reach_px - 0.5), 0, size - 1).astype(np.int64)  # texel indices (x, y)
    hi = np.clip(np.ceil(p.max(1) + reach_px - 0.5), 0, size - 1).astype(np.int64)
    n = np.where(usable[:, None], hi - lo + 1, 0)
    count = n[:, 0] * n[:, 1]
    best = np.full(size * size, -np.inf)
    triangle = np.full(size * size, -1, np.int64)
    bary = np.zeros((size * size, 3))
    before = np.concatenate([[0], np.cumsum(count)])  # pairs before each triangle
    start = 0
    while start < len(count):
        end = max(int(np.searchsorted(before, before[start] + chunk_pairs, "right")) - 1, start + 1)
        f = np.repeat(np.arange(start, end), count[start:end])
        local = np.arange(len(f)) - np.repeat(before[start:end] - before[start], count[start:end])
        x = lo[f, 0] + local % n[f, 0]
        y = lo[f, 1] + local // n[f, 0]
        b = barycentric(p[f], np.stack([x + 0.5, y + 0.5], -1))
        edge_len = np.linalg.norm(p[f][:, [2, 0, 1]] - p[f][:, [1, 2, 0]], axis=-1)  # edge opposite each corner
        depth_px = (b * (2 * np.abs(signed[f]))[:, None] / np.maximum(edge_len, 1e-12)).min(1)
        key = depth_px - 1e6 * turned[f]
        keep = depth_px >= -reach_px
        texel = (y * size + x)[keep]
        key, f, b = key[keep], f[keep], b[keep]
        order = np.argsort(key, kind="stable")[::-1]  # deepest first: np.unique keeps each texel's first
        texel, first = np.unique(texel[order], return_index=True)
        pick = order[first]
        better = key[pick] > best[texel]
        texel, pick = texel[better], pick[better]
        best[texel], triangle[texel] = key[pick], f[pick]
        b = np.clip(b[pick], 0.0, None)
        bary[texel] = b / b.sum(1, keepdims=True)
        start = end
    return TexelSurface(triangle.reshape(size, size), bary.reshape(size, size, 3).astype(np.float32))


def barycentric(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(M,3) barycentric weights of 2-D points (M,2) in triangles (M,3,2), unclamped (negative outside):
    w_k = area(point, next two corners) / area(triangle)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    cross = lambda u, v: u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    area = cross(b - a, c - a)
    area = np.where(np.abs(area) < 1e-18, 1e-18, area)
    w1 = cross(points - a, c - a) / area
    w2 = cross(b - a, points - a) / area
    return np.stack([1 - w1 - w2, w1, w2], -1)


def sample_bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(M,C) an image (H,W,C) at continuous pixel coordinates (M,) x right, y down, pixel centres at k + 0.5 (as a
    camera's pixels and a texture's texels are), edges clamped.

    >>> sample_bilinear(np.array([[[0.0], [1.0]], [[2.0], [3.0]]]), np.array([1.0, 0.0]), np.array([1.0, 1.5])).tolist()
    [[1.5], [2.0]]
    """
    img = np.asarray(image, np.float32)
    h, w = img.shape[:2]
    gx, gy = np.asarray(x, np.float64) - 0.5, np.asarray(y, np.float64) - 0.5
    x0, y0 = np.floor(gx), np.floor(gy)
    fx, fy = (gx - x0)[:, None], (gy - y0)[:, None]
    xa, xb = np.clip(x0, 0, w - 1).astype(np.int64), np.clip(x0 + 1, 0, w - 1).astype(np.int64)
    ya, yb = np.clip(y0, 0, h - 1).astype(np.int64), np.clip(y0 + 1, 0, h - 1).astype(np.int64)
    top = img[ya, xa] * (1 - fx) + img[ya, xb] * fx
    bottom = img[yb, xa] * (1 - fx) + img[yb, xb] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)


def bake_views(avatar: Avatar, n_yaws: int) -> list[tuple[float, float]]:
    """(yaw_deg, pitch_deg) of the bake's cameras about the head (0, 0: in front): n_yaws across the yaws the
    avatar can show (a turntable's sweep, those views_beyond left out; all round where it went all round) at the
    height of the head, and every other one of them again from as high and as low as its capture's cameras went
    (30 degrees where it did not record them), for the crown and under the chin."""
    sweep = avatar.card.turntable_sweep_deg()
    if sweep == 0.0:
        yaws = sorted((360.0 * k / n_yaws + 180.0) % 360.0 - 180.0 for k in range(n_yaws))  # the front among them
    else:
        while sweep > 0 and (avatar.card.views_beyond(sweep) or avatar.card.views_beyond(-sweep)):
            sweep -= 0.5  # the turntable's sweep reaches as far as the farther side: keep both sides in view
        yaws = [float(y) for y in np.linspace(-sweep, sweep, n_yaws)] if n_yaws > 1 else [0.0]
    pitch = (avatar.card.view_range or {}).get("pitch_deg", [-30.0, 30.0])
    return ([(y, 0.0) for y in yaws] + [(y, float(pitch[1])) for y in yaws[::2]]
            + [(y, float(pitch[0])) for y in yaws[1::2]])


class ViewBlend:
    """Each point's colour over the views seen so far, weighted by how squarely each sees it: a running softmax of
    cos / FEATHER_COS over the views that see the point (cos > MIN_COS), kept relative to the best cos so far so
    that no weight overflows: on a new best m', the sums so far scale by exp((m - m') / FEATHER_COS)."""

    def __init__(self, n_points: int):
        self.best = np.full(n_points, MIN_COS)  # the squarest view's cos so far
        self.weight = np.zeros(n_points)
        self.sum = np.zeros((n_points, 3))
        self.view = np.full(n_points, -1)  # the squarest view so far (-1: none)

    def add(self, view: int, cos: np.ndarray, rgb: np.ndarray) -> None:
        """A view's cos (M,) (0 where it does not see the point) and colours (M,3)."""
        seen = cos > MIN_COS
        best = np.maximum(self.best, np.where(seen, cos, -np.inf))
        scale = np.exp((self.best - best) / FEATHER_COS)
        w = np.where(seen, np.exp((np.minimum(cos, best) - best) / FEATHER_COS), 0.0)
        self.weight = self.weight * scale + w
        self.sum = self.sum * scale[:, None] + w[:, None] * rgb
        self.view = np.where(seen & (cos > self.best), view, self.view)
        self.best = best

    def colour(self) -> np.ndarray:
        """(M,3) the blended colours (0 where no view saw the point)."""
        return (self.sum / np.maximum(self.weight, 1e-300)[:, None]).astype(np.float32)


def bake_texture(avatar: Avatar, chart: Chart, size: int, render_px: int, n_yaws: int, rasterizer: Rasterizer,
                 preset: str = "preview", on_view: Callable[[int, int], None] | None = None) -> BakedTexture:
    """The avatar's colour at rest on the chart's texture (size x size): its renders of render_px from bake_views'
    cameras, at the preset's render settings (samples, passes; a preset's smaller image is left out: the texture's
    detail is the renders'); on_view(done, total) after each render."""
    controls = avatar.card.at_rest(Controls())
    posed = np.asarray(avatar.frame_geometry(controls, rasterizer).posed.detach().cpu(), np.float64)
    triangles = np.asarray(avatar.head_model.triangles)
    surface = texel_surface(chart.uv, chart.triangles, size)
    cover = surface.covered.ravel()
    corners = chart.vertex_of[chart.triangles[surface.triangle.ravel()[cover]]]  # (M,3) head-model vertices
    b = surface.bary.reshape(-1, 3)[cover, :, None]
    points = (posed[corners] * b).sum(1)
    normals = (vertex_normals(posed, triangles)[corners] * b).sum(1)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    views = bake_views(avatar, n_yaws)
    options = RenderOptions(buffers=(), quality=avatar.card.presets[preset].quality)  # not its scale: render_px it is
    px = render_px
    background = avatar.background_colour()
    blend = ViewBlend(len(points))
    for k, (yaw, pitch) in enumerate(views):
        camera = avatar.card.turntable_camera(yaw, px, pitch)
        images = render_image(avatar, camera, controls, options, rasterizer)
        raster = rasterizer.rasterize(posed.astype(np.float32), triangles, camera)
        blend.add(k, *seen_from(camera, raster, images, background, points, normals))
        if on_view:
            on_view(k + 1, len(views))
    colour, view_of = blend.colour(), blend.view
    seen = np.zeros(size * size, bool)
    seen[np.flatnonzero(cover)[view_of >= 0]] = True
    image = np.zeros((size * size, 3), np.float32)
    image[np.flatnonzero(cover)] = colour
    filled = push_pull(image.reshape(size, size, 3), seen.reshape(size, size))
    view = np.full(size * size, -1)
    view[np.flatnonzero(cover)] = view_of
    return BakedTexture(np.round(np.clip(filled, 0, 1) * 255).astype(np.uint8), surface.covered,
                        seen.reshape(size, size), view.reshape(size, size), views, px)


def seen_from(camera: Camera, raster: Raster, images: dict[str, np.ndarray], background: np.ndarray,
              points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How squarely the camera sees each point (cos of the angle between its normal and the way to the camera; 0
    where it does not see it: behind it, outside the image, hidden, or where the render is more background (3,)
    than avatar) and the avatar's colour there, the background taken out of the render's: (M,), (M,3)."""
    x, y, depth = project(camera, points)
    to_eye = camera.position[None] - points
    cos = (normals * to_eye).sum(1) / np.maximum(np.linalg.norm(to_eye, axis=1), 1e-12)
    h, w = raster.depth.shape
    inside = (depth > 0) & (x >= 0) & (x < w) & (y >= 0) & (y < h) & (cos > 0)
    nearest = raster.depth[np.clip(y.astype(np.int64), 0, h - 1), np.clip(x.astype(np.int64), 0, w - 1)]
    pixel_m = depth / camera.intrinsics[1]
    slack = DEPTH_SLACK_M + 1.5 * pixel_m * np.sqrt(np.clip(1 - cos**2, 0, 1)) / np.maximum(cos, 0.1)
    opacity = sample_bilinear(images["opacity"][..., None], x, y)[:, 0]
    visible = inside & (depth <= nearest + slack) & (opacity >= MIN_OPACITY)
    rgb = sample_bilinear(images["rgb"], x, y)
    own = (rgb - (1.0 - opacity[:, None]) * background) / np.maximum(opacity, MIN_OPACITY)[:, None]
    return np.where(visible, cos, 0.0), np.clip(own, 0.0, 1.0)


def texture_image(raster: Raster, uv: np.ndarray, triangles: np.ndarray, texture: np.ndarray) -> np.ndarray:
    """(H,W,3) float in [0,1]: a textured mesh as a viewer draws it, where the raster sees it (0 elsewhere): each
    pixel's texture coordinate interpolated from its triangle's corners (uv (N,2), triangles (F,3) on the N
    vertices the raster was drawn with) and the texture (rows top first) looked up bilinearly."""
    hit = raster.hit
    out = np.zeros((*hit.shape, 3), np.float32)
    t = (np.asarray(uv, np.float64)[np.asarray(triangles)[raster.triangle[hit]]] * raster.bary[hit][..., None]).sum(1)
    size_y, size_x = texture.shape[:2]
    out[hit] = sample_bilinear(np.asarray(texture, np.float32) / 255.0, t[:, 0] * size_x, t[:, 1] * size_y)
    return out
