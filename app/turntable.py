"""Turntables: the avatar seen from a camera circling it, optionally talking, as an H.264 mp4 and PNG frames;
with the quality presets and the display of render buffers they need. Shared by the `render` and `turntable`
commands and the studio."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import replace

import numpy as np
from PIL import Image

from app.configs import TurntableConfig
from models.avatars.base import Avatar
from models.head.controls import Controls
from render.camera import turntable_camera
from render.gl.raster import Rasterizer

INSPECT = {"rgb_no_shadows": "rgb_no_shadows", "rgb_light": "rgb_light", "shadow_change": "rgb_no_shadows",
           "shading": "rgb_flat"}
"""Buffers shown from an avatar's inspection buffers (render_image(inspect=True)): which one each needs."""

PLAIN = ("rgb", "depth", "opacity")
"""Buffers every render makes."""


def render_needs(buffer: str) -> tuple[tuple[str, ...], bool]:
    """What a render must make to show `buffer`: the optional buffers (render_image's `buffers`) and whether the
    inspection buffers (`inspect`). Nothing else is made: a primitives avatar's colour render composites 3 channels
    where its normals and light make 7.

    >>> render_needs("rgb"), render_needs("normals"), render_needs("shadow_change")
    (((), False), (('normals',), False), ((), True))
    """
    if buffer in INSPECT:
        return (), True
    return ((), False) if buffer in PLAIN else ((buffer,), False)


def needs_covered(shown: str, wanted: str) -> bool:
    """Whether a render made to show `shown` has what `wanted` needs (no new render when switching to it).

    >>> needs_covered("normals", "rgb"), needs_covered("rgb", "normals"), needs_covered("rgb_light", "shading")
    (True, False, True)
    """
    (have, inspect), (need, inspecting) = render_needs(shown), render_needs(wanted)
    return set(need) <= set(have) and (inspect or not inspecting)


def buffer_image(buffers: dict[str, np.ndarray], name: str) -> np.ndarray:
    """A buffer of the neural render as (H,W,3) uint8 for display."""
    if name == "shadow_change":  # what the pose's and expression's shadow inputs change: darker = shadowed
        img = (0.5 + 2.0 * (buffers["rgb"] - buffers["rgb_no_shadows"]).mean(-1))[..., None].repeat(3, 2)
        return (np.clip(img, 0, 1) * 255).round().astype(np.uint8)
    if name == "shading":  # the render minus the render with every normal facing the viewer, signed about grey
        return (np.clip(0.5 + 2.0 * (buffers["rgb"] - buffers["rgb_flat"]), 0, 1) * 255).round().astype(np.uint8)
    b = buffers[name]
    if name in ("normals", "grad_normals"):
        img = b * 0.5 + 0.5
    elif name == "depth":
        finite = np.isfinite(b)
        lo, hi = (b[finite].min(), b[finite].max()) if finite.any() else (0.0, 1.0)
        img = np.where(finite, 1 - (b - lo) / max(hi - lo, 1e-6), 0)[..., None].repeat(3, 2)
    elif name == "opacity":
        img = b[..., None].repeat(3, 2)
    else:
        img = b
    return (np.clip(img, 0, 1) * 255).round().astype(np.uint8)


def resized(image: np.ndarray, size: int) -> np.ndarray:
    """An (H,W,3) uint8 image at size x size, Lanczos-filtered: a preset's smaller render scaled up to the size asked
    for, a larger picture (a driver's frame) down."""
    if image.shape[:2] == (size, size):
        return image
    return np.asarray(Image.fromarray(image).resize((size, size), Image.Resampling.LANCZOS))


def talking(avatar: Avatar, base: Controls, phase: float) -> Controls:
    """Controls with the jaw (or the expressions named like it) and a smile moving with `phase` (radians)."""
    head = avatar.head_model
    expr = np.zeros(head.num_expression, np.float32)
    expr[: len(base.expression)] = base.expression[: head.num_expression]
    names = [n.lower() for n in head.expr_names]
    for i, n in enumerate(names):
        if "jaw" in n and "open" in n:
            expr[i] = 0.5 * (1 - math.cos(phase * 3))
        elif "smile" in n:
            expr[i] = 0.5 * (1 - math.cos(phase))
    jaw = base.jaw
    if "jaw" in head.joint_names:  # a jaw joint (FLAME, the built-in head) opens the mouth by rotation
        jaw = np.array([0.2 * (1 - math.cos(phase * 3)), 0.0, 0.0], np.float32)
    return replace(base, expression=expr, jaw=jaw)


def turntable_frames(avatar: Avatar, rasterizer: Rasterizer, cfg: TurntableConfig,
                     controls: Controls | None = None, on_frame: Callable[[int], None] | None = None,
                     should_stop: Callable[[], bool] | None = None) -> Iterator[np.ndarray]:
    """(size,size,3) uint8 frames of the turntable (the preset may render fewer pixels: scaled up); on_frame(k)
    after each."""
    size = avatar.apply_preset(cfg.preset, cfg.size)
    controls = avatar.at_rest(controls or Controls())
    sweep = avatar.turntable_sweep_deg() if cfg.sweep_deg is None else cfg.sweep_deg
    for k in range(cfg.frames):
        phase = 2 * math.pi * k / cfg.frames
        yaw = sweep * math.sin(phase) if sweep else math.degrees(phase)
        cam = turntable_camera(avatar.rest_vertices(), yaw, cfg.elevation_deg, fov_y_deg=18.0,
                               width_px=size, height_px=size, zoom=cfg.zoom)
        c = talking(avatar, controls, phase) if cfg.animate else controls
        yield resized(buffer_image(avatar.render_image(c, cam, rasterizer, should_stop=should_stop, buffers=()),
                                   "rgb"), cfg.size)
        if on_frame:
            on_frame(k)
