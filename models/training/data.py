"""A capture split in memory for training: images, rays, per-frame head geometry and the rasterized surface
distance of every pixel. build_frames reads the files and rasterizes the frames; the trainer is built from
what it returns."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from models.avatars.base import Avatar
from models.capture.dataset import CaptureSplit
from models.capture.frames import camera_of, foreground_reach_m, load_mask, load_rgb
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.rays import camera_directions


@dataclass
class FrameSet:
    """N frames of one split, H x W."""

    split: CaptureSplit
    images: torch.Tensor  # (N,H,W,3)
    masks: torch.Tensor | None  # (N,H,W) coverage, if the capture has masks
    origins: torch.Tensor  # (N,3)
    directions: torch.Tensor  # (N,H,W,3) world, unit
    surface_t: torch.Tensor  # (N,H,W) inf where the pixel misses the mesh
    active: torch.Tensor  # (N,H,W) bool: where training draws rays (the avatar's training_pixels)
    geometry: list[Any]  # the avatar's frame_geometry of each frame
    active_index: list[torch.Tensor]  # per frame, the flat indices of its active pixels (training draws rays here)
    plate: torch.Tensor | None = None  # (H*W,3) the background plate behind every frame's rays, if the capture has one

    def __len__(self) -> int:
        return len(self.images)


@dataclass(frozen=True)
class ValidationFrame:
    """The frame whose PSNR the training log follows."""

    controls: Any
    camera: Any
    image: np.ndarray  # (H,W,3)


def build_frames(split: CaptureSplit, avatar: Avatar, gl: GLContext) -> FrameSet:
    """Read the split's images (and masks), make each frame's geometry, rasterize the posed mesh for the surface
    distance along each pixel's ray, and let the avatar fit its settings to the capture and choose where
    training draws rays."""
    bg = avatar.background.numpy()
    images, masks, origins, dirs, surf, geos, rasters, cameras, reach = [], [], [], [], [], [], [], [], []
    d = camera_directions(camera_of(split, np.eye(4)))  # every frame of a split has the same intrinsics
    dirs_cam = (d / np.linalg.norm(d, axis=-1, keepdims=True)).astype(np.float32)
    raster = Rasterizer(gl)
    for f in split.frames:
        images.append(load_rgb(f.image_path, bg))
        geo = avatar.frame_geometry(f.controls, raster)
        cam = camera_of(split, f.camera_to_world)
        r = raster.rasterize(geo.posed.cpu().numpy(), avatar.head_model.triangles, cam)
        if "mask_path" in f.extra:
            masks.append(load_mask(f.extra["mask_path"]))
            reach.append(foreground_reach_m(r.hit, r.depth, masks[-1], cam.focal_px()))
        surf.append(r.distance.astype(np.float32))
        origins.append(f.camera_to_world[:3, 3])
        dirs.append(dirs_cam @ f.camera_to_world[:3, :3].T)
        geos.append(geo)
        rasters.append(r)
        cameras.append(cam)
    raster.release()
    has_masks = len(masks) == len(images) and len(images) > 0
    avatar.fit_to_capture(np.concatenate(reach) if has_masks else None)
    active = [avatar.training_pixels(cam, r) for r, cam in zip(rasters, cameras, strict=True)]
    t = lambda a, dt=torch.float32: torch.as_tensor(np.stack(a), dtype=dt)
    active_t = t(active, torch.bool)
    plate = avatar.plate_for(cameras[0]) if cameras else None
    return FrameSet(split, t(images), t(masks) if has_masks else None, t(origins), t(dirs), t(surf), active_t, geos,
                    [torch.nonzero(a.ravel()).squeeze(1) for a in active_t], None if plate is None else plate.cpu())


def validation_frame(split: CaptureSplit, background: np.ndarray) -> ValidationFrame:
    """The split's first frame, read."""
    f = split.frames[0]
    return ValidationFrame(f.controls, camera_of(split, f.camera_to_world), load_rgb(f.image_path, background))
