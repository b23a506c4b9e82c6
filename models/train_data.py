"""A capture split in memory for training and evaluation: images, rays, per-frame head geometry and the
rasterized surface distance of every pixel."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch
from PIL import Image

from models.avatar import Avatar, FrameGeometry, active_pixels, foreground_reach_m
from models.dataset import CaptureSplit, DatasetError
from models.head.head import posed_mesh
from models.nerface import NerfaceAvatar, NerfaceGeometry
from render.camera import Camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer, surface_distance


def camera_of(split: CaptureSplit, c2w: np.ndarray) -> Camera:
    _, fy, cx, cy = split.intrinsics
    if abs(cx - split.width / 2) > 0.5 or abs(cy - split.height / 2) > 0.5:
        raise DatasetError(f"{split.folder}: principal point ({cx}, {cy}) off the image centre is not supported yet")
    fov = math.degrees(2 * math.atan(0.5 * split.height / fy))
    return Camera(np.linalg.inv(c2w), fov, split.width, split.height, near_m=0.05, far_m=10.0)


def camera_directions(split: CaptureSplit) -> np.ndarray:
    """(H,W,3) camera-space ray directions (unit), OpenGL axes."""
    fx, fy, cx, cy = split.intrinsics
    j, i = np.meshgrid(np.arange(split.width) + 0.5, np.arange(split.height) + 0.5)
    d = np.stack([(j - cx) / fx, -(i - cy) / fy, -np.ones_like(j)], -1)
    return (d / np.linalg.norm(d, axis=-1, keepdims=True)).astype(np.float32)


def load_rgb(path, background: np.ndarray | None = None) -> np.ndarray:
    with Image.open(path) as im:
        a = np.asarray(im.convert("RGBA" if im.mode in ("RGBA", "LA") else "RGB"), np.float32) / 255.0
    if a.shape[-1] == 4:
        bg = np.ones(3, np.float32) if background is None else background
        a = a[..., :3] * a[..., 3:] + bg * (1 - a[..., 3:])
    return a


@dataclass
class FrameSet:
    """N frames of one split, H x W."""

    split: CaptureSplit
    images: torch.Tensor  # (N,H,W,3)
    masks: torch.Tensor | None  # (N,H,W) coverage, if the capture has masks
    origins: torch.Tensor  # (N,3)
    directions: torch.Tensor  # (N,H,W,3) world, unit
    surface_t: torch.Tensor  # (N,H,W) inf where the pixel misses the mesh
    active: torch.Tensor  # (N,H,W) bool: pixels rendered (near the mesh's silhouette; NerFACE: the face box)
    geometry: list[FrameGeometry | NerfaceGeometry]
    active_index: list[torch.Tensor]  # per frame, the flat indices of its active pixels (training draws rays here)

    def __len__(self) -> int:
        return len(self.images)


def face_box(hit: np.ndarray, margin_px: int) -> np.ndarray:
    """(H,W) the bounding box of the mesh's pixels grown by margin_px: where NerFACE draws most rays."""
    box = np.zeros_like(hit)
    if hit.any():
        rows, cols = np.nonzero(hit.any(1))[0], np.nonzero(hit.any(0))[0]
        top, left = max(rows[0] - margin_px, 0), max(cols[0] - margin_px, 0)
        box[top:rows[-1] + margin_px + 1, left:cols[-1] + margin_px + 1] = True
    return box


def build_frames(split: CaptureSplit, avatar: Avatar | NerfaceAvatar, gl: GLContext) -> FrameSet:
    bg = avatar.background.numpy()
    images, masks, origins, dirs, surf, active, geos = [], [], [], [], [], [], []
    dirs_cam = camera_directions(split)
    raster = Rasterizer(gl)
    rasters, cameras, reach = [], [], []
    for f in split.frames:
        images.append(load_rgb(f.image_path, bg))
        geo = avatar.geometry(f.controls)
        if isinstance(avatar, Avatar):
            geo = avatar.with_light(geo, raster)
        cam = camera_of(split, f.camera_to_world)
        r = raster.rasterize(posed_mesh(avatar.head, f.controls)[0], avatar.head_model.triangles, cam)
        if "mask_path" in f.extra:
            masks.append(np.asarray(Image.open(f.extra["mask_path"]).convert("L"), np.float32) / 255.0)
            reach.append(foreground_reach_m(r.hit, r.depth, masks[-1], cam.focal_px()))
        surf.append(surface_distance(r, -dirs_cam[..., 2]))  # -z: the view-axis part of each unit direction
        origins.append(f.camera_to_world[:3, 3])
        dirs.append(dirs_cam @ f.camera_to_world[:3, :3].T)
        geos.append(geo)
        rasters.append(r)
        cameras.append(cam)
    raster.release()
    if isinstance(avatar, Avatar) and len(masks) == len(images) and images:
        # Render only as far beyond the mesh as the capture's foreground goes (99.9% of its pixels, + 2 mm):
        # none of the shell's width where the capture shows nothing there.
        spread = np.concatenate(reach)
        avatar.render_cfg = replace(avatar.render_cfg, silhouette_m=float(
            (np.quantile(spread, 0.999) if len(spread) else 0.0) + 0.002))
    for r, cam in zip(rasters, cameras, strict=True):
        if isinstance(avatar, NerfaceAvatar):
            active.append(face_box(r.hit, margin_px=max(2, split.width // 32)))
        else:
            active.append(active_pixels(avatar.render_cfg, cam, r))
    t = lambda a, dt=torch.float32: torch.as_tensor(np.stack(a), dtype=dt)
    active_t = t(active, torch.bool)
    return FrameSet(split, t(images), t(masks) if len(masks) == len(images) else None, t(origins), t(dirs), t(surf),
                    active_t, geos, [torch.nonzero(a.ravel()).squeeze(1) for a in active_t])
