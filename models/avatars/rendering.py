"""An avatar's buffers as images, the same for every model: the rays of a camera's pixels in batches through the
model's `render_rays`, cancellable between batches, scattered back into images (render_image). How it renders is
one frozen value (RenderOptions), passed down to the model with each batch: nothing is set on the model."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import torch

from models.avatars.base import BACKGROUND, BASE_LAYOUT, Avatar, RenderCancelled
from models.avatars.card import AvatarCard
from models.avatars.quality import Quality
from models.head.controls import Controls
from render.camera import Camera, clipping_around
from render.gl.raster import Rasterizer
from render.normals import depth_normal_image, mesh_normal_image, surface_normal_image
from render.rays import Raster, Rays, image_rays, pixel_rays, rays_to_images


@dataclass(frozen=True)
class RenderOptions:
    """How one image is rendered: which codes, which buffers, how it may be cancelled and spread over cores.

    A model's render_rays is given the value render_image renders with, its `buffers` then the optional buffers the
    image makes (of default_buffers and the inspection buffers asked for)."""

    frame: int | None = None
    """A training frame whose codes the avatar renders with; None: the codes new controls take (the mean code, or
    the nearest training frames')."""
    inspect: bool = False
    """Add the inspection buffers the avatar declares (inspection_buffers)."""
    buffers: tuple[str, ...] | None = None
    """Which of the optional buffers to make (None: all; rgb, opacity and depth always come): a model may leave out
    the work of the others."""
    chunk_rays: int | None = None
    """Rays a batch (None: the avatar's chunk_rays; smaller batches let a newer request in sooner)."""
    should_stop: Callable[[], bool] | None = None
    """Asked between batches, and within a batch by a model whose batches are long (the primitives' march, between
    its waves); yes raises RenderCancelled (a newer request won)."""
    cores: int | None = None
    """Cores a model may spread one batch's work over (the primitives' march groups); None: torch's thread count."""
    quality: Quality | None = None
    """The render's samples (and a second pass, bf16) where the model has such knobs: a preset's (preset_options);
    None: the avatar's own, those it trained with. The image size is the camera's."""
    room: np.ndarray | None = None
    """(H,W,3) what this camera saw behind the person, at the camera's size: a frame's own room, where the capture's
    camera moved (frame_room); None: the avatar's plate where the camera is the capture's, else its colour."""
    time_s: float | None = None
    """Where the controls are a frame of the avatar's own capture (a held-out frame, the timeline): its time in the
    video, which the codes may follow (components/codes.py); None: new controls (sliders, another video)."""


def preset_options(card: AvatarCard, preset: str, size: int, options: RenderOptions = RenderOptions()
                   ) -> tuple[RenderOptions, int]:
    """`options` with one of the avatar's presets (draft, preview, final: card.presets) and the image size that
    preset renders at for a requested size (a draft renders smaller, shown scaled up)."""
    quality = card.presets[preset].quality
    return replace(options, quality=quality), quality.size(size)


def render_image(avatar: Avatar, camera: Camera, controls: Controls, options: RenderOptions = RenderOptions(),
                 rasterizer: Rasterizer | None = None) -> dict[str, np.ndarray]:
    """The avatar's buffers as images (H,W,...) for these controls seen by `camera`, rendered as `options` says;
    `rasterizer` (None: none) draws the posed guide mesh for the models that sample about it."""
    device = avatar.background.device
    geo = avatar.frame_geometry(controls, rasterizer, options.time_s).to(device)
    camera = clipping_around(camera, geo.posed.cpu().numpy())  # the head may be anywhere (a translation)
    rays, idx = pixel_rays_of(avatar, geo, camera, rasterizer)
    plate = avatar.plate.for_camera(camera) if options.room is None else room_pixels(options.room, camera, device)
    if plate is not None:
        rays = replace(rays, background=plate[torch.as_tensor(idx, device=plate.device)].cpu())
    rays = rays.to(device)
    names = avatar.inspection_buffers() if options.inspect else ()
    wanted = tuple(b for b in avatar.default_buffers() if options.buffers is None or b in options.buffers)
    surface = avatar.normals_from_surface and "normals" in wanted
    wanted = tuple(b for b in wanted if not (surface and b == "normals"))
    parts: dict[str, list[torch.Tensor]] = {k: [] for k in (*BASE_LAYOUT, *wanted, *names)}
    batch_options = replace(options, buffers=(*wanted, *names))
    with avatar.display_mode(options):
        chunk = options.chunk_rays or avatar.chunk_rays
        for a in range(0, len(rays), chunk):
            if options.should_stop is not None and options.should_stop():
                raise RenderCancelled
            out = avatar.render_rays(rays[a:a + chunk], geo, options.frame, options=batch_options)
            made = out.buffers | avatar.inspect(out, geo, names)
            made["depth"] = torch.where(made["opacity"] > 0.5, made["depth"], torch.full_like(made["depth"], np.inf))
            for k, v in made.items():
                if k in parts:  # a model that makes a buffer anyway: kept where asked for
                    parts[k].append(v.detach())
    background = (avatar.background if plate is None else plate).cpu().numpy()
    layout = {k: (c, background if fill == BACKGROUND else fill) for k, (c, fill) in avatar.layout().items()}
    images = rays_to_images(parts, camera.height_px, camera.width_px, idx, layout)
    if surface:
        images["normals"] = surface_normals(avatar, images["depth"], geo, camera, rasterizer)
    return images


def room_pixels(room: np.ndarray, camera: Camera, device) -> torch.Tensor:
    """(H*W,3) a frame's room (h,w,3) at the camera's image size (area-averaged where it is another)."""
    room = np.asarray(room, np.float32)
    if room.shape[:2] != (camera.height_px, camera.width_px):
        import cv2

        room = cv2.resize(room, (camera.width_px, camera.height_px), interpolation=cv2.INTER_AREA)
    return torch.as_tensor(room.reshape(-1, 3), device=device)


def pixel_rays_of(avatar: Avatar, geometry, camera: Camera, rasterizer: Rasterizer | None) -> tuple[Rays, np.ndarray]:
    """The rays of the pixels this avatar renders (image_pixels), and their flat pixel indices; the guide mesh is
    rasterized for them where the avatar reads its raster (reads_raster) and there is a rasterizer."""
    origin, dirs = image_rays(camera)
    raster = Raster.empty(camera.height_px, camera.width_px) if rasterizer is None or not avatar.reads_raster else \
        rasterizer.rasterize(geometry.posed.cpu().numpy(), avatar.head_model.triangles, camera)
    idx = np.nonzero(avatar.image_pixels(camera, raster).ravel())[0]
    surface_t = torch.as_tensor(raster.distance.ravel()[idx], dtype=torch.float32)
    return Rays(origin.expand(len(idx), 3), dirs[idx], surface_t), idx


def surface_normals(avatar: Avatar, depth: np.ndarray, geometry, camera: Camera, rasterizer: Rasterizer | None
                    ) -> np.ndarray:
    """(H,W,3) the normals of the surface a depth image (distance along each pixel's ray, inf where nothing is
    drawn) shows, joined to the posed guide mesh's where it lies on the mesh (render/normals.py); the depth's
    alone without a rasterizer. The depth's normals are smoothed over 2 px at 256 px, alike at other sizes (on
    three of the demo's test frames they are 15.5-17.9 degrees from the truth in the median at 2 px, 18.0-21.5 at
    1 px, 13.2-14.7 at 4 px)."""
    origin, directions = pixel_rays(camera)
    from_depth = depth_normal_image(origin, directions, depth, sigma_px=max(camera.height_px, camera.width_px)
                                    / 128.0)
    if rasterizer is None:
        return from_depth
    posed = geometry.posed.detach().cpu().numpy()
    raster = rasterizer.rasterize(posed, avatar.head_model.triangles, camera)
    return surface_normal_image(from_depth, depth, mesh_normal_image(raster, posed, avatar.head_model.triangles),
                                raster.distance)
