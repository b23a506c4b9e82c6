"""Rays through a camera's pixels and what a rasterized mesh tells them: pure numpy/torch, no GL. The GL
rasterizer (render/gl/raster.py) fills a Raster (triangle, depth, barycentrics and each ray's distance to the
surface, met with the triangle's plane here); per-ray results go back into images."""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import torch

from render.camera import Camera
from render.mesh import cross


@dataclass(frozen=True)
class Coverage:
    """Which pixels of a camera see a mesh, and how deep: H x W, rows top first (what choosing the pixels to render
    or train needs: Rasterizer.coverage, without the ray math of a Raster)."""

    triangle: np.ndarray  # (H,W) int, -1 where the pixel sees no surface
    depth: np.ndarray  # (H,W) metres along the view axis, inf where no surface

    @property
    def hit(self) -> np.ndarray:
        return self.triangle >= 0


@dataclass(frozen=True)
class Raster(Coverage):
    """What a camera's pixels see of a mesh, H x W, rows top first: the coverage and where on its triangle each
    pixel's ray meets the surface."""

    bary: np.ndarray  # (H,W,3) barycentric coordinates of the visible point (0 where no surface)
    distance: np.ndarray
    """(H,W) metres along each pixel's unit ray to the visible point, inf where no surface: the ray met with its
    triangle's plane in float64, so that a crop of a camera, whose rays are the same, gets the same distances
    (the GL depth differs between the two in its last bits)."""

    @staticmethod
    def empty(height_px: int, width_px: int) -> Raster:
        """A camera's view of no mesh at all."""
        shape = (height_px, width_px)
        return Raster(np.full(shape, -1), np.full(shape, np.inf), np.zeros((*shape, 3)), np.full(shape, np.inf))


@dataclass(frozen=True)
class Rays:
    """R rays: where they start, where they go, how far along each the guide mesh's surface lies, and (where the
    scene has a background plate) what each sees behind the avatar."""

    origins: torch.Tensor  # (R,3) world, metres
    directions: torch.Tensor  # (R,3) unit
    surface_t: torch.Tensor  # (R,) distance to the rasterized surface, inf where the ray misses it
    background: torch.Tensor | None = None
    """(R,3) the colour behind the avatar along each ray (a capture's background plate); None: the avatar's
    background colour."""

    def __post_init__(self):
        R = len(self.origins)
        assert self.origins.shape == (R, 3) and self.directions.shape == (R, 3) and self.surface_t.shape == (R,), \
            (tuple(self.origins.shape), tuple(self.directions.shape), tuple(self.surface_t.shape))
        assert self.background is None or self.background.shape == (R, 3), tuple(self.background.shape)

    def __len__(self) -> int:
        return len(self.origins)

    def __getitem__(self, idx: slice | torch.Tensor) -> Rays:
        return Rays(self.origins[idx], self.directions[idx], self.surface_t[idx],
                    None if self.background is None else self.background[idx])

    def to(self, device: torch.device | str) -> Rays:
        return Rays(self.origins.to(device), self.directions.to(device), self.surface_t.to(device),
                    None if self.background is None else self.background.to(device))


def camera_directions(camera: Camera) -> np.ndarray:
    """(H,W,3) directions through pixel centres in camera space (OpenGL axes: -z ahead, +y up), not normalised,
    z = -1: ((u - cx) / fx, -(v - cy) / fy, -1) for pixel centres (u, v), rows top first."""
    h, w = camera.height_px, camera.width_px
    j, i = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    if camera.centred:  # the centred camera's form, so that its rays stay bit for bit what they were
        t = np.tan(np.radians(camera.fov_y_deg) / 2)
        return np.stack([(2 * j / w - 1) * t * w / h, (1 - 2 * i / h) * t, -np.ones_like(j)], -1)
    fx, fy, cx, cy = camera.intrinsics
    return np.stack([(j - cx) / fx, -(i - cy) / fy, -np.ones_like(j)], -1)


def pixel_directions(intrinsics, width_px: int, pixels: np.ndarray) -> np.ndarray:
    """(R,3) unit directions in camera space through the centres of some pixels (flat indices, rows top first) of
    any pinhole camera (fx, fy, cx, cy): camera_directions' ((u - cx) / fx, -(v - cy) / fy, -1), normalised in
    float64, for those pixels alone (a frame of a following crop has its own principal point; its (H,W,3) table is
    not kept).

    >>> d = pixel_directions((100.0, 100.0, 10.0, 20.0), 64, np.array([20 * 64 + 9]))  # pixel (9, 20): centre
    >>> d.round(6)  # (9.5, 20.5), half a pixel left of and below the principal point: (-0.005, -0.005, -1) / 1.000025
    array([[-0.005   , -0.005   , -0.999975]])
    """
    j, i = pixels % width_px + 0.5, pixels // width_px + 0.5
    fx, fy, cx, cy = intrinsics
    d = np.stack([(j - cx) / fx, -(i - cy) / fy, -np.ones_like(j)], -1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


RAYS_KEPT = 2
"""pixel_rays keeps the rays of this many cameras: a frame asks for its camera's three times (its rays, the guide
mesh's raster, the normals buffer), 3-6 ms each at 256 px."""
_kept: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_kept_lock = threading.Lock()


def pixel_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """World origin (3,) and unit directions (H,W,3) through pixel centres, rows top first; read-only (the last
    RAYS_KEPT cameras' are kept and shared).

    >>> from render.camera import look_at
    >>> cam = Camera(look_at(np.zeros(3), np.array([0.0, 0.0, -1.0])), 30.0, 4, 2)
    >>> o, d = pixel_rays(cam); again = pixel_rays(Camera(cam.view.copy(), 30.0, 4, 2))
    >>> again[1] is d, d.flags.writeable, d.shape
    (True, False, (2, 4, 3))
    """
    key = (np.asarray(camera.view, np.float64).tobytes(), camera.fov_y_deg, camera.width_px, camera.height_px,
           camera.cx_px, camera.cy_px, camera.fx_px)
    with _kept_lock:
        if key in _kept:
            _kept.move_to_end(key)
            return _kept[key]
    d_cam = camera_directions(camera)
    c2w = np.linalg.inv(camera.view)
    d = d_cam @ c2w[:3, :3].T
    rays = c2w[:3, 3], d / np.linalg.norm(d, axis=-1, keepdims=True)
    for a in rays:
        a.flags.writeable = False
    with _kept_lock:
        _kept[key] = rays
        while len(_kept) > RAYS_KEPT:
            _kept.popitem(last=False)
    return rays


def image_rays(camera: Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """The camera's origin (1,3) and its pixels' unit ray directions (H*W,3), float32, rows top first."""
    origin, dirs = pixel_rays(camera)
    return (torch.from_numpy(np.array(origin, np.float32))[None],  # float32 copies of pixel_rays' shared arrays
            torch.from_numpy(np.array(dirs.reshape(-1, 3), np.float32)))


def ray_triangle_hit(origin: np.ndarray, dirs: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates (N,3) and distance t (N,) along the rays (in units of |dirs|) where rays
    (origin, (N,3) dirs) meet the planes of (N,3,3) triangles (Moller-Trumbore without the inside test: the
    rasterizer already chose the triangle); t is nan where a ray runs along its triangle's plane.

    >>> bary, t = ray_triangle_hit(np.zeros(3), np.array([[0.0, 0.0, -1.0]]),
    ...                            np.array([[[-1.0, -1.0, -2.0], [1.0, -1.0, -2.0], [0.0, 1.0, -2.0]]]))
    >>> t.tolist(), bary.round(3).tolist()  # the plane z = -2, 2 m ahead; (0, 0) = 1/4 v0 + 1/4 v1 + 1/2 v2
    ([2.0], [[0.25, 0.25, 0.5]])
    """
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = cross(dirs, e2)
    det = np.einsum("ij,ij->i", e1, p)
    det = np.where(np.abs(det) < 1e-20, 1e-20, det)
    s = origin - tri[:, 0]
    u = np.einsum("ij,ij->i", s, p) / det
    q = cross(s, e1)
    v = np.einsum("ij,ij->i", dirs, q) / det
    t = np.einsum("ij,ij->i", e2, q) / det
    t = np.where(np.abs(det) > 1e-18, t, np.nan)
    return np.clip(np.stack([1 - u - v, u, v], -1), 0.0, 1.0), t


def rays_to_images(parts: dict[str, list[torch.Tensor]], height: int, width: int, idx: np.ndarray,
                   layout: dict[str, tuple[int, np.ndarray | float]]) -> dict[str, np.ndarray]:
    """Images (H,W) or (H,W,C) from per-ray results computed in chunks for the flat pixel indices `idx`
    ((R,) or (R,C) per chunk). layout: each buffer's channels (0: a scalar image) and the value of the
    pixels not rendered.

    >>> imgs = rays_to_images({"depth": [torch.tensor([2.0])]}, 1, 2, np.array([1]), {"depth": (0, np.inf)})
    >>> imgs["depth"].tolist()
    [[inf, 2.0]]
    """
    out = {}
    for k, chunks in parts.items():
        channels, fill = layout[k]
        shape = (channels,) if channels else ()
        img = np.zeros((height * width, *shape), np.float32)
        img[:] = fill
        if len(idx):
            img[idx] = torch.cat(chunks).float().cpu().numpy().reshape(len(idx), *shape)
        out[k] = img.reshape(height, width, *shape)
    return out
