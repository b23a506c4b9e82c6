"""A capture split in memory for training: images, rays, per-frame head geometry and the rasterized surface
distance of every pixel. build_frames reads the files and rasterizes the frames; the trainer is built from
what it returns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from models.avatars.base import Avatar
from models.capture.dataset import CaptureSplit
from models.capture.frames import camera_of, foreground_reach_m, load_mask, load_rgb
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.rays import Rays, camera_directions


@dataclass
class FrameSet:
    """N frames of one split, H x W."""

    split: CaptureSplit
    images: torch.Tensor  # (N,H,W,3)
    masks: torch.Tensor | None  # (N,H,W) coverage, if the capture has masks
    origins: torch.Tensor  # (N,3)
    camera_directions: torch.Tensor  # (H*W,3) unit, camera space: every frame of a split has the same intrinsics
    rotations: torch.Tensor  # (N,3,3) float64, camera to world
    surface_t: torch.Tensor  # (N,H,W) inf where the pixel misses the mesh
    geometry: list[Any]  # the avatar's frame_geometry of each frame
    active_index: list[torch.Tensor]  # per frame, the flat indices of the pixels training draws rays from (the
    # avatar's training_pixels)
    plate: torch.Tensor | None = None  # (H*W,3) the background plate behind every frame's rays, if the capture has one

    def __len__(self) -> int:
        return len(self.images)

    def rays(self, frame: int, pixels: torch.Tensor) -> Rays:
        """The rays of a frame's pixels (flat indices), their world directions made here from the camera's and the
        frame's rotation: a frame's own (H,W,3) directions are not kept (0.75 MB a frame at 256 px, gigabytes for a
        long video)."""
        d = (self.camera_directions[pixels].double() @ self.rotations[frame].T).float()
        return Rays(self.origins[frame].expand(len(pixels), 3), d, self.surface_t[frame].reshape(-1)[pixels],
                    None if self.plate is None else self.plate[pixels])


@dataclass(frozen=True)
class ValidationFrame:
    """The frame whose PSNR the training log follows."""

    controls: Any
    camera: Any
    image: np.ndarray  # (H,W,3)


def build_frames(split: CaptureSplit, avatar: Avatar, gl: GLContext,
                 on_frame: Callable[[int, int], None] | None = None) -> FrameSet:
    """Read the split's images (and masks), make each frame's geometry, rasterize the posed mesh for the surface
    distance along each pixel's ray, and let the avatar fit its settings to the capture and choose where
    training draws rays. One frame at a time into tensors made once: what a frame's raster holds (3 MB at 256 px)
    is not kept for every frame of a long video, the mesh is rasterized again once the avatar's settings are
    fitted. on_frame(done, total) after each frame is read (a long video takes minutes)."""
    bg = avatar.background.numpy()
    n = len(split.frames)
    d = camera_directions(camera_of(split, np.eye(4)))  # every frame of a split has the same intrinsics
    dirs_cam = (d / np.linalg.norm(d, axis=-1, keepdims=True)).astype(np.float32)
    H, W = dirs_cam.shape[:2]
    images, surf = torch.empty(n, H, W, 3), torch.empty(n, H, W)
    has_masks = n > 0 and all("mask_path" in f.extra for f in split.frames)
    masks = torch.empty(n, H, W) if has_masks else None
    geos, cameras, reach = [], [], []
    raster = Rasterizer(gl)
    tris = avatar.head_model.triangles
    for k, f in enumerate(split.frames):
        images[k] = torch.from_numpy(np.asarray(load_rgb(f.image_path, bg), np.float32))
        geo = avatar.frame_geometry(f.controls, raster)
        cam = camera_of(split, f.camera_to_world)
        r = raster.rasterize(geo.posed.cpu().numpy(), tris, cam)
        if has_masks:
            mask = load_mask(f.extra["mask_path"])
            masks[k] = torch.from_numpy(np.asarray(mask, np.float32))
            reach.append(foreground_reach_m(r.hit, r.depth, mask, cam.focal_px()))
        surf[k] = torch.from_numpy(r.distance.astype(np.float32))
        geos.append(geo)
        cameras.append(cam)
        if on_frame is not None:
            on_frame(k + 1, n)
    avatar.fit_to_capture(np.concatenate(reach) if has_masks else None)
    active = []
    for geo, cam in zip(geos, cameras, strict=True):  # the pixels as the fitted settings see them
        pixels = avatar.training_pixels(cam, raster.rasterize(geo.posed.cpu().numpy(), tris, cam))
        active.append(torch.from_numpy(np.flatnonzero(pixels)))
    raster.release()
    plate = avatar.plate_for(cameras[0]) if cameras else None
    rotations = torch.as_tensor(np.stack([np.asarray(f.camera_to_world, np.float64)[:3, :3] for f in split.frames]))
    origins = torch.as_tensor(np.stack([f.camera_to_world[:3, 3] for f in split.frames]), dtype=torch.float32)
    return FrameSet(split, images, masks, origins, torch.from_numpy(dirs_cam.reshape(-1, 3)), rotations, surf,
                    geos, active, None if plate is None else plate.cpu())


def validation_frame(split: CaptureSplit, background: np.ndarray) -> ValidationFrame:
    """The split's first frame, read."""
    f = split.frames[0]
    return ValidationFrame(f.controls, camera_of(split, f.camera_to_world), load_rgb(f.image_path, background))
