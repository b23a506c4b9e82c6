"""`avatar-studio reenact`: a performance video drives an avatar.

The driving video is tracked with the project's tracker (app/track.py: landmarks, one crop, the head model
fitted to every frame); what the driver does is carried onto the avatar relative to the driver's own neutral frame
(the calmest one unless named) by models/tracking/retarget.py, which live driving in the studio uses too.

The result is an animation (app/animation.py, one key a tracked frame, linear) saved beside the mp4, which
the studio opens on its timeline and `animate` renders again; the mp4 shows the driver's frames and the
avatar side by side, or the avatar alone. Where expressions cannot be carried across head models, the command
says so.
"""

from __future__ import annotations

import json
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.animation import SLIDER_RANGES, Animation, AnimationError, animation_frames, load_animation, save_animation
from app.configs import ReenactConfig
from app.display import resized
from app.errors import UserInputError
from app.progress import Progress
from app.track import TrackConfig, track_video
from models.files import atomic_write_bytes
from models.head.controls import Controls
from models.head.model import HeadModel
from models.head.sources import load_head
from models.tracking.retarget import Retarget, calmest_frame, retarget_frames
from models.tracking.retarget import expression_map as expression_map  # the command's tests name it here

LIMITS = {key: SLIDER_RANGES[key] for key in ("expression", "jaw.open", "gaze")}
"""Carried values are kept inside the Controls panel's slider ranges."""


def retarget(controls: list[Controls], times: list[float], driver: HeadModel, avatar: HeadModel,
             neutral: int | None = None, fps: float = 30.0) -> tuple[Animation, Retarget]:
    """The driver's tracked frames (controls at times, seconds from the first; frames sampled at fps) as an
    animation of the avatar's sliders, relative to the driver's neutral frame; one linear key a frame."""
    n = calmest_frame(controls) if neutral is None else neutral
    if not 0 <= n < len(controls):
        raise UserInputError(f"--neutral-frame {neutral}: the video gave {len(controls)} tracked frames")
    per_frame, how = retarget_frames(controls, driver, avatar, n, LIMITS)
    tracks: dict[str, list[tuple[float, float]]] = {}
    for channels, t in zip(per_frame, times, strict=True):
        for channel, v in channels.items():
            tracks.setdefault(channel, []).append((round(t, 6), round(v, 6)))
    # Seen from the front, as the driver's camera saw the driver.
    tracks["camera.yaw"], tracks["camera.pitch"] = [(0.0, 0.0)], [(0.0, 0.0)]
    fps = float(np.clip(fps, 1, 240))
    anim = Animation(fps=fps, duration_s=times[-1] + 1.0 / fps,
                     interpolation="linear", tracks={c: tuple(k) for c, k in tracks.items()})
    return anim, how


@dataclass
class Driver:
    """The performance: its frames' controls, their times (seconds from the first), the rate they play at, the
    head model they are in, each frame's picture, and what the report says of how they were had."""

    controls: list[Controls]
    times: list[float]
    fps: float
    head: HeadModel
    head_spec: str
    picture: Callable[[int], np.ndarray]
    """Frame k's picture (RGB uint8), for the side-by-side video."""
    report: dict
    seconds: float


def driver_from_video(cfg: ReenactConfig, head: HeadModel, head_spec: str) -> Driver:
    t0 = time.perf_counter()
    tracked = track_video(TrackConfig(cfg.video, cfg.out, head=head_spec, landmarker=cfg.landmarker, fps=cfg.fps,
                                      seconds=cfg.seconds, size=cfg.size, iterations=cfg.iterations, overlay=False),
                          head)
    times = [f["time_s"] - tracked.kept[0]["time_s"] for f in tracked.kept]
    report = {"frames_read": tracked.read, "landmark_error_px_median": round(float(np.median(tracked.errors)), 3),
              "crop": {"x0": tracked.framing.x0, "y0": tracked.framing.y0, "side": tracked.framing.side,
                       "following": tracked.framing.following},
              "source_frames": [f["source_frame"] for f in tracked.kept]}
    return Driver(tracked.result.controls, times, min(cfg.fps or tracked.info.fps, tracked.info.fps), head, head_spec,
                  lambda k: tracked.kept[k]["image"], report, time.perf_counter() - t0)


def capture_of(folder: Path) -> Path:
    """A capture folder, or an avatar folder's capture (the one it was trained on, from its provenance)."""
    if (folder / "avatar.json").is_file():
        try:
            prov = json.loads((folder / "avatar.json").read_text()).get("provenance", {})
        except (OSError, json.JSONDecodeError, AttributeError):
            raise UserInputError(f"{folder / 'avatar.json'}: not readable as JSON") from None
        for dataset in (prov.get("dataset_resolved"), prov.get("dataset")):
            if dataset and Path(dataset).is_dir():
                return Path(dataset)
        raise UserInputError(f"{folder}: the capture this avatar was trained on is not on this machine; give the "
                             "capture folder (or a video) instead")
    return folder


def driver_from_capture(cfg: ReenactConfig, avatar_head: HeadModel, avatar_spec: str) -> Driver:
    """Another person's capture (or an avatar's, "drive B from A's frames"): its frames' controls as they are,
    played at --fps (default 30), the first --seconds of them."""
    from models.capture.dataset import load_split
    from models.capture.frames import load_rgb

    t0 = time.perf_counter()
    folder = capture_of(cfg.video)
    split = load_split(folder, "train")
    if split.head_model is None:
        raise UserInputError(f"{folder}: a capture without a head model (NerFACE's) cannot drive an avatar")
    fps = cfg.fps or 30.0
    frames = [f for k, f in enumerate(split.frames) if not cfg.seconds or k / fps < cfg.seconds]
    if not frames:
        raise UserInputError(f"{folder}: no frames in its train split")
    head = avatar_head if split.head_model == avatar_spec else load_head(split.head_model)
    background = np.asarray(split.background, np.float32) if not isinstance(split.background, Path) else \
        np.zeros(3, np.float32)
    return Driver([f.controls for f in frames], [k / fps for k in range(len(frames))], fps, head, split.head_model,
                  lambda k: (np.clip(load_rgb(frames[k].image_path, background), 0, 1) * 255).round().astype(np.uint8),
                  {"capture": str(folder), "frames_read": len(frames)}, time.perf_counter() - t0)


def run_reenact(cfg: ReenactConfig) -> int:
    from app.avatar_commands import check_video_size, frames_folder, guide_mesh_writer, open_avatar
    from render.gl.context import GLContext
    from render.gl.raster import Rasterizer
    from render.video import write_video

    if cfg.out.suffix.lower() != ".mp4":
        raise UserInputError(f"{cfg.out}: the performance is written as an .mp4")
    check_video_size(cfg.size)
    signal.signal(signal.SIGTERM, interrupted)  # the studio's Cancel: as Ctrl-C, no partial mp4 is left
    pngs = frames_folder(cfg.out, cfg.pngs, "performance")
    anim_path = cfg.out.with_suffix(".json")
    if anim_path.exists():
        try:
            load_animation(anim_path)
        except AnimationError:
            raise UserInputError(f"{anim_path}: the performance's animation goes there, and it holds another file; "
                                 "choose another --out") from None
    avatar, meta = open_avatar(cfg.avatar)
    write_mesh = guide_mesh_writer(avatar, cfg.out, cfg.meshes)
    if cfg.video.is_dir():
        driver = driver_from_capture(cfg, avatar.head_model, meta["head_model"])
    else:
        spec = cfg.driver_head or meta["head_model"]
        driver = driver_from_video(cfg, avatar.head_model if not cfg.driver_head else load_head(spec), spec)
    anim, how = retarget(driver.controls, driver.times, driver.head, avatar.head_model, cfg.neutral_frame, driver.fps)
    if how.note:
        print(f"reenact: {how.note}", flush=True)
    print(f"reenact: driver's neutral frame {how.neutral}; {len(how.carried)} expressions carried"
          + (f", {len(how.missing)} of the driver's have no counterpart" if how.missing else ""), flush=True)

    def driver_image(t: float) -> np.ndarray:
        return driver.picture(int(np.argmin(np.abs(np.asarray(driver.times) - t))))

    bar = Progress("reenact", anim.frames)
    gl = GLContext.headless()
    t1 = time.perf_counter()

    def frames():
        rendered = animation_frames(avatar, Rasterizer(gl), anim, cfg.size, cfg.preset,
                                    on_frame=lambda k: bar.update(k + 1), on_pose=write_mesh)
        for t, image in zip(anim.times(), rendered, strict=True):
            yield np.concatenate([resized(driver_image(t), cfg.size), image], 1) if cfg.side_by_side else image

    n = write_video(frames(), cfg.out, anim.fps, pngs)
    t_render = time.perf_counter() - t1
    save_animation(anim, anim_path)
    read = driver.report["frames_read"]
    report = {"driver": str(cfg.video), "avatar": str(cfg.avatar), "driver_head": driver.head_spec,
              "frames_driving": len(driver.controls), "frames_written": n, "neutral_frame": how.neutral,
              "expressions_carried": how.carried, "expressions_missing": how.missing, "note": how.note,
              "preset": cfg.preset, "size": cfg.size,
              "seconds": {"track": round(driver.seconds, 2), "render": round(t_render, 2)},
              "seconds_per_frame": {"track": round(driver.seconds / max(read, 1), 4),
                                    "render": round(t_render / max(n, 1), 4)}, **driver.report}
    atomic_write_bytes(cfg.out.with_name(cfg.out.stem + "_report.json"), (json.dumps(report, indent=1) + "\n").encode())
    what = "tracking" if not cfg.video.is_dir() else "reading the capture"
    print(f"wrote {cfg.out} ({n} frames at {anim.fps:g} fps{', driver beside the avatar' if cfg.side_by_side else ''})"
          f" and its animation {anim_path}; {what} {driver.seconds:.1f} s "
          f"({report['seconds_per_frame']['track']:.3f} s a frame), rendering {t_render:.1f} s "
          f"({report['seconds_per_frame']['render']:.3f} s a frame, {cfg.preset})")
    return 0


def interrupted(signum, frame) -> None:
    raise KeyboardInterrupt

