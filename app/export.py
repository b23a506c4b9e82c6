"""`avatar-studio export`: an avatar as a glTF 2.0 binary for other tools (models/export/), with an animation file's
keys carried into glTF animation channels."""

from __future__ import annotations

import time

import numpy as np

from app.animation import (
    POSE_CHANNELS,
    Animation,
    AnimationError,
    check_channels,
    expression_index,
    load_animation,
    rest_sliders,
)
from app.avatar_commands import open_avatar
from app.configs import ExportConfig
from app.errors import UserInputError
from app.head_commands import _check_out
from app.progress import progress_callback
from app.sliders import View
from app.web import GLB_NAME, check_web_out, write_web_folder
from models.export.keys import Clip, morph_keys, pose_frames
from models.files import atomic_write_bytes
from models.head.head import Head
from models.head.model import HeadModel

ROTATION_CHANNELS = (*POSE_CHANNELS, "jaw.open", "gaze.yaw", "gaze.pitch")
"""The channels that turn joints (the rest: expressions, carried as morph weights, and the camera's, left out)."""


def animation_clip(anim: Animation, head: HeadModel, name: str) -> Clip:
    """An animation as a glTF clip: the expression channels' keys as morph-weight keys (exactly: linear keys as
    LINEAR, smooth ones as CUBICSPLINE), the rotation channels sampled at its frames as `animate` renders them (the
    head model's joints, from the rest sliders: models/head/head.py's full_pose). ControlsError where a channel
    turns a joint the head model lacks (ICT's jaw)."""
    expressions = {}
    for channel, keys in anim.tracks.items():  # in the file's order: a later channel on the same expression wins
        group, _, expr = channel.partition(".")
        if group == "expression":
            expressions[expression_index(head, expr)] = keys
    pose = None
    if any(c in ROTATION_CHANNELS for c in anim.tracks):
        times = np.asarray(anim.times())
        controls = [anim.pose_at(float(t), rest_sliders(head), View(), head)[0].controls() for t in times]
        pose = pose_frames(times, Head(head).full_pose(controls).cpu().numpy())
    return Clip(name, morph_keys(expressions, head.num_expression, anim.interpolation), pose)


def run_export(cfg: ExportConfig) -> int:
    from models.export.avatar_gltf import BakeSettings, export_glb
    from render.gl.context import GLContext
    from render.gl.raster import Rasterizer

    if cfg.format == "web":
        check_web_out(cfg.out)
    else:
        _check_out(cfg.out, (".glb",))
    avatar, _ = open_avatar(cfg.avatar)
    clip = None
    if cfg.animation is not None:
        try:
            anim = load_animation(cfg.animation)
            check_channels(anim, avatar.head_model, str(cfg.animation))
        except AnimationError as e:
            raise UserInputError(str(e)) from None
        clip = animation_clip(anim, avatar.head_model, cfg.animation.stem)
    settings = BakeSettings(cfg.texture_size, cfg.render_size, cfg.views, cfg.preset)
    t0 = time.perf_counter()
    done = export_glb(avatar, Rasterizer(GLContext.headless()), settings, clip,
                      progress_callback("baking the texture", "views"))
    if cfg.format == "web":
        files = write_web_folder(cfg.out, done.data)
        where = (f"{cfg.out}/ (the player and three.js, {len(files)} files, "
                 f"{sum(f.stat().st_size for f in files) / 1e6:.1f} MB; to see it: python3 -m http.server -d "
                 f"{cfg.out}, then http://localhost:8000/) with {cfg.out / GLB_NAME}")
    else:
        atomic_write_bytes(cfg.out, done.data)
        where = str(cfg.out)
    skipped = sorted(c for c in anim.tracks if c.startswith("camera.")) if clip is not None else []
    print(f"wrote {where} ({summary(done, clip, skipped)}) in {time.perf_counter() - t0:.1f} s")
    return 0


def summary(done, clip: Clip | None, skipped: list[str]) -> str:
    """What the file holds, in a line."""
    mesh, texture = done.mesh, done.texture
    joints = "no skeleton" if mesh.skin is None else f"{len(mesh.skin.names)} joints ({', '.join(mesh.skin.names)})"
    keys = ""
    if clip is not None:
        parts = [f"{len(clip.morph.times)} morph-weight keys" if clip.morph else "",
                 f"{len(clip.pose.rotations)} joints turning over {len(clip.pose.times)} frames" if clip.pose else ""]
        keys = (f"; animation '{clip.name}': {', '.join(p for p in parts if p) or 'nothing to carry'}"
                + (f" ({', '.join(skipped)} left out: a glTF viewer has its own camera)" if skipped else ""))
    return (f"{len(done.data) / 1e6:.1f} MB: {len(mesh.positions)} vertices of which {done.chart.seam_copies} seam "
            f"copies, {len(mesh.triangles)} triangles, {len(mesh.morph_names)} morph targets, {joints}; a "
            f"{texture.image.shape[0]} px texture ({done.chart.source} UVs), {100 * texture.seen_share:.0f}% of the "
            f"chart's texels seen by {len(texture.views)} renders of {texture.render_px} px, the rest filled{keys}")
