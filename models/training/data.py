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
from models.avatars.components.plate import camera_key, plate_window
from models.capture.dataset import CaptureSplit, DatasetError
from models.capture.frames import (
    camera_of,
    foreground_reach_m,
    frame_camera,
    frame_room,
    has_alpha,
    load_mask,
    load_rgb,
    load_rgb8,
)
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.rays import Rays, camera_directions, pixel_directions


@dataclass
class FrameSet:
    """N frames of one split, H x W."""

    split: CaptureSplit
    images: torch.Tensor  # (N,H,W,C) uint8 as the files hold them, C = 4 where they have alpha (target composites)
    background: torch.Tensor  # (3,) what an image's alpha composites over
    origins: torch.Tensor  # (N,3)
    camera_directions: torch.Tensor  # (H*W,3) unit, camera space, of the split's intrinsics
    rotations: torch.Tensor  # (N,3,3) float64, camera to world
    surface_t: torch.Tensor | None  # (N,H,W) inf where none (Avatar.training_surface); None: training reads none
    # (Avatar.trains_on_surface)
    geometry: list[Any]  # the avatar's frame_geometry of each frame
    active_index: list[torch.Tensor]  # per frame, the flat indices of the pixels training draws rays from (the
    # avatar's training_pixels)
    plate: torch.Tensor | None = None  # (Hp*Wp,3) the background plate behind the frames' rays, if the capture has one
    # (uint8: the frames' own rooms stacked, a frame's window each)
    own_intrinsics: list[tuple[float, float, float, float] | None] | None = None  # per frame, where not the split's
    plate_windows: list[tuple[int, int]] | None = None  # per frame, its image's top-left in the plate (x0, y0)
    plate_width: int = 0  # Wp

    def __len__(self) -> int:
        return len(self.images)

    @property
    def pixel_count(self) -> int:
        """H * W."""
        return self.images.shape[1] * self.images.shape[2]

    def target(self, frame: int, pixels: torch.Tensor) -> torch.Tensor:
        """(R,3) float32 colours of a frame's pixels (flat indices): load_rgb's, bit for bit (the bytes / 255, alpha
        composited over the background), made for these pixels alone: a frame is kept as its bytes (0.19 MB at
        256 px, where float32 colours took 0.75)."""
        px = self.images[frame].reshape(-1, self.images.shape[-1])[pixels].float() / 255.0
        if px.shape[1] == 3:
            return px
        return px[:, :3] * px[:, 3:] + self.background * (1 - px[:, 3:])

    def rays(self, frame: int, pixels: torch.Tensor) -> Rays:
        """The rays of a frame's pixels (flat indices), their world directions made here from the camera's and the
        frame's rotation: a frame's own (H,W,3) directions are not kept (0.75 MB a frame at 256 px, gigabytes for a
        long video). A frame with its own intrinsics (a following crop's) has its directions made for these pixels
        alone, and its plate read from its window of it."""
        own = None if self.own_intrinsics is None else self.own_intrinsics[frame]
        if own is None:
            d_cam = self.camera_directions[pixels].double()
        else:
            d_cam = torch.from_numpy(pixel_directions(own, self.images.shape[2], pixels.numpy()).astype(np.float32))
            d_cam = d_cam.double()
        d = (d_cam @ self.rotations[frame].T).float()
        behind = None if self.plate is None else self.plate[self.plate_pixels(frame, pixels)]
        if behind is not None and behind.dtype == torch.uint8:  # frames' own rooms, kept as their bytes
            behind = behind.float() / 255.0
        surface_t = torch.full((len(pixels),), float("inf")) if self.surface_t is None else \
            self.surface_t[frame].reshape(-1)[pixels].float()  # (as render_image gives a model that reads no raster)
        return Rays(self.origins[frame].expand(len(pixels), 3), d, surface_t, behind)

    def plate_pixels(self, frame: int, pixels: torch.Tensor) -> torch.Tensor:
        """A frame's pixels (flat indices) as the plate's (its window's place in the plate)."""
        if self.plate_windows is None:
            return pixels
        x0, y0 = self.plate_windows[frame]
        w = self.images.shape[2]
        return (pixels // w + y0) * self.plate_width + pixels % w + x0


@dataclass(frozen=True)
class ValidationFrame:
    """The frame whose PSNR the training log follows."""

    controls: Any
    camera: Any
    image: np.ndarray  # (H,W,3)
    room: np.ndarray | None = None  # (H,W,3) its own room, where the capture keeps one a frame (frame_room)
    time_s: float | None = None  # its time in the video (Frame.time_s)


READING, PLACING = "reading the frames", "placing the mesh in the frames"
"""build_frames' two passes, as its on_frame names them."""


def build_frames(split: CaptureSplit, avatar: Avatar, gl: GLContext,
                 on_frame: Callable[[str, int, int], None] | None = None) -> FrameSet:
    """Read the split's images (and masks), make each frame's geometry, rasterize the posed mesh (for the surface
    distance along each pixel's ray, where the avatar's training reads it: trains_on_surface), and let the avatar
    fit its settings to the
    capture and choose where training draws rays. One frame at a time into tensors made once: what a frame's
    raster holds (3 MB at 256 px) is not kept for every frame of a long video, the mesh is rasterized again once the
    avatar's settings are fitted; the masks only say how far the person reaches (not kept), the images are kept as
    bytes, the training pixels' indices as int32. on_frame(READING, done, total) after each frame is read (a long
    video takes minutes), then on_frame(PLACING, done, total) as each is rasterized again for its training pixels."""
    n = len(split.frames)
    d = camera_directions(camera_of(split, np.eye(4)))  # the split's intrinsics (frames may have their own)
    dirs_cam = (d / np.linalg.norm(d, axis=-1, keepdims=True)).astype(np.float32)
    H, W = dirs_cam.shape[:2]
    images = torch.empty(n, H, W, 4 if any(has_alpha(f.image_path) for f in split.frames) else 3, dtype=torch.uint8)
    # A model whose training rays need no distance to the mesh (Avatar.trains_on_surface) gets the coverage alone,
    # as the second pass does: half the time, and no (N,H,W) distances kept (256 KB a frame at 256 px). One that
    # reads no raster where it renders (a term of its loss reads the distances: the primitives' face depth) keeps
    # them in half precision (steps of 1 mm at 1 m, 2 at 2 m; 128 KB a frame at 256 px).
    surf = torch.empty(n, H, W, dtype=torch.float32 if avatar.reads_raster else torch.float16) \
        if avatar.trains_on_surface else None
    has_masks = n > 0 and all("mask_path" in f.extra for f in split.frames)
    geos, cameras, reach = [], [], []
    raster = Rasterizer(gl)
    tris = avatar.head_model.triangles
    for k, f in enumerate(split.frames):
        rgb = load_rgb8(f.image_path)
        if rgb.shape[-1] < images.shape[-1]:  # an opaque frame among frames with alpha
            rgb = np.concatenate([rgb, np.full_like(rgb[..., :1], 255)], -1)
        images[k] = torch.from_numpy(np.array(rgb))  # (PIL's array is read-only)
        geo = avatar.frame_geometry(f.controls, raster)
        cam = frame_camera(split, f)
        r = (raster.rasterize if surf is not None else raster.coverage)(geo.posed.cpu().numpy(), tris, cam)
        if has_masks:
            mask = load_mask(f.extra["mask_path"])
            reach.append(foreground_reach_m(r.hit, r.depth, mask, cam.focal_px()))
        if surf is not None:
            surf[k] = torch.from_numpy(avatar.training_surface(r).astype(np.float32)).to(surf.dtype)
        geos.append(geo)
        cameras.append(cam)
        if on_frame is not None:
            on_frame(READING, k + 1, n)
    avatar.fit_to_capture(np.concatenate(reach) if has_masks else None)
    active = []
    for k, (geo, cam) in enumerate(zip(geos, cameras, strict=True)):  # the pixels as the fitted settings see them
        pixels = avatar.training_pixels(cam, raster.coverage(geo.posed.cpu().numpy(), tris, cam))
        active.append(torch.from_numpy(np.flatnonzero(pixels).astype(np.int32)))
        if on_frame is not None:
            on_frame(PLACING, k + 1, n)
    raster.release()
    plate, windows, plate_width = frames_on_plate(split, avatar, cameras)
    own = [f.intrinsics for f in split.frames]
    rotations = torch.as_tensor(np.stack([np.asarray(f.camera_to_world, np.float64)[:3, :3] for f in split.frames]))
    origins = torch.as_tensor(np.stack([f.camera_to_world[:3, 3] for f in split.frames]), dtype=torch.float32)
    background = avatar.background.detach().cpu().float()
    return FrameSet(split, images, background, origins, torch.from_numpy(dirs_cam.reshape(-1, 3)), rotations, surf,
                    geos, active, plate, None if all(k is None for k in own) else own, windows, plate_width)


def frames_on_plate(split: CaptureSplit, avatar: Avatar, cameras: list
                    ) -> tuple[torch.Tensor | None, list[tuple[int, int]] | None, int]:
    """The avatar's plate (Hp*Wp,3) and where each frame's image lies in it (None where every frame sees it whole,
    as a fixed crop's do), its width; (None, None, 0) without a plate. A frame whose camera sees no part of the
    plate is an error naming it (its rays would composite over nothing the capture recorded). Where the capture
    keeps each frame's own room (a camera that moved: frame_room), the rooms stacked one below the other are the
    plate, each frame its own window of it."""
    if split.frames and all("room_path" in f.extra for f in split.frames):
        rooms = []
        for f in split.frames:  # kept as their bytes, as the frames are (rays() makes the colours of a batch's)
            rooms.append(np.round(frame_room(f) * 255.0).astype(np.uint8))
            if rooms[-1].shape[:2] != (split.height, split.width):
                h, w = rooms[-1].shape[:2]
                raise DatasetError(f"{f.extra['room_path']}: the frame's room is {w}x{h} pixels; the capture's "
                                   f"images are {split.width}x{split.height}")
        h = rooms[0].shape[0]
        return torch.from_numpy(np.concatenate(rooms, 0).reshape(-1, 3)), [(0, k * h) for k in range(len(rooms))], \
            split.width
    if all(f.intrinsics is None for f in split.frames):
        plate = avatar.plate.for_camera(cameras[0]) if cameras else None
        return None if plate is None else plate.cpu(), None, 0
    key = avatar.plate.camera
    if key is None:
        return None, None, 0
    key, windows = key.cpu().numpy(), []
    for f, cam in zip(split.frames, cameras, strict=True):
        w = plate_window(key, camera_key(cam))
        if w is None or w[2:] != (cam.width_px, cam.height_px):
            raise DatasetError(f"{split.folder / f'transforms_{split.split}.json'}: frame {f.index}: its camera "
                               f"(intrinsics {list(split.frame_intrinsics(f))}) sees no window of the background plate")
        windows.append(w[:2])
    return avatar.plate.image.reshape(-1, 3).cpu(), windows, int(key[0])


def validation_frame(split: CaptureSplit, background: np.ndarray, index: int = 0) -> ValidationFrame:
    """One of the split's frames (the first), read."""
    f = split.frames[index]
    return ValidationFrame(f.controls, frame_camera(split, f), load_rgb(f.image_path, background), frame_room(f),
                           f.time_s)
