"""Turntables: the avatar seen from a camera circling it, optionally talking, as an H.264 mp4 and PNG frames at a
quality preset. Shared by the `turntable` command and the studio's Export panel."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import replace

import numpy as np

from app.configs import TurntableConfig
from app.display import buffer_image, resized
from models.avatars.base import Avatar
from models.avatars.rendering import RenderOptions, preset_options, render_image
from models.head.controls import Controls
from render.gl.raster import Rasterizer


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
    options, size = preset_options(avatar.card, cfg.preset, cfg.size,
                                   RenderOptions(should_stop=should_stop, buffers=()))
    controls = avatar.card.at_rest(controls or Controls())
    sweep = avatar.card.turntable_sweep_deg() if cfg.sweep_deg is None else cfg.sweep_deg
    for k in range(cfg.frames):
        phase = 2 * math.pi * k / cfg.frames
        yaw = sweep * math.sin(phase) if sweep else math.degrees(phase)
        cam = avatar.card.turntable_camera(yaw, size, cfg.elevation_deg, cfg.zoom)
        c = talking(avatar, controls, phase) if cfg.animate else controls
        yield resized(buffer_image(render_image(avatar, cam, c, options, rasterizer), "rgb"), cfg.size)
        if on_frame:
            on_frame(k)
