"""`train`, `eval` and `render`: make an avatar from a capture, measure it, draw it."""

from __future__ import annotations

import json
import shlex
import signal
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from app.configs import AnimateConfig, EvalConfig, ExportMeshConfig, PersonalizeConfig, RenderCommandConfig
from app.display import INSPECT, buffer_image, render_needs, resized
from app.errors import UserInputError
from app.head_commands import save_png
from app.progress import Progress, progress_by_stage, progress_callback
from app.turntable import TurntableConfig, turntable_frames
from models.avatars.checkpoint import CheckpointError
from models.avatars.effects import parse_effects
from models.avatars.registry import load_avatar, load_prior, training_start
from models.avatars.rendering import RenderOptions, preset_options, render_image
from models.avatars.whole.avatar import WholeHeadAvatar
from models.capture.dataset import check_images, is_capture, load_split
from models.capture.frames import background_plate, frame_camera, frame_room, load_mask, load_rgb
from models.capture.synthetic import read_png16
from models.device import device_of
from models.files import FolderBusy, WriterLock, atomic_write_bytes, foreign_files
from models.head.controls import Controls, load_controls
from models.training.configs import PERSONALIZE_LR
from models.training.metrics import (
    face_mse,
    image_offset_px,
    luminance,
    normal_angles_deg,
    pearson,
    psnr,
    ssim,
)
from models.training.prior import PriorTrainConfig, corpus_folders, distributed_from_env, prepare_prior
from models.training.trainer import DEFAULT_STEPS, PROGRESS_SECONDS, TrainConfig, prepare_training
from models.training.whole import compose
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.raster import Rasterizer
from render.video import write_video


def open_avatar(folder: Path, device: str = "cpu"):
    """load_avatar, where a capture given in an avatar's place is named as one."""
    if not (folder / "avatar.json").exists() and is_capture(folder):
        raise UserInputError(f"{folder}: is a capture dataset, not an avatar (train one with: avatar-studio train "
                             f"{folder})")
    return load_avatar(folder, device)


def run_train(cfg: TrainConfig) -> int:
    device_of(cfg.device)  # before any work: a clear error where there is no GPU
    try:
        parse_effects(cfg.effects or "all")
    except ValueError as e:
        raise UserInputError(f"--effects {cfg.effects}: {e}") from None
    try:
        lock = WriterLock(cfg.out, "avatar-studio train").__enter__()
    except FolderBusy as e:
        raise UserInputError(str(e)) from None
    except OSError as e:
        raise UserInputError(f"{cfg.out}: cannot write the avatar there ({e.strerror})") from None
    try:  # held until training ends, however it ends
        return train_locked(cfg)
    finally:
        lock.__exit__()


def train_locked(cfg: TrainConfig) -> int:
    """run_train with the avatar folder's writer lock held."""
    if not cfg.resume and (cfg.out / "avatar.json").exists():
        raise UserInputError(f"{cfg.out}: already holds an avatar; pass --resume to continue it or choose a new folder")
    gl = GLContext.headless()
    reading = progress_by_stage()
    if cfg.resume and (cfg.out / WHOLE_PARTS).is_dir():  # a whole head's parts: each continued, then put together
        return train_whole(cfg, gl, None)
    if cfg.resume:
        trainer = prepare_training(cfg, gl, on_frame=reading)
    else:
        try:
            split = load_split(cfg.dataset, "train")
            way, prior, why = training_start(split.head_model, split.tracked, cfg.model, cfg.from_scratch, cfg.prior)
        except CheckpointError as e:  # a prior asked for that is none, or of another head model: names the folder
            raise UserInputError(str(e)) from None
        print(f"training {cfg.out} {why}", flush=True)
        if way == WholeHeadAvatar.name:
            return train_whole(cfg, gl, prior)
        if prior is None:
            trainer = prepare_training(cfg, gl, on_frame=reading)
        else:
            trainer, _ = personalizing_trainer(replace(cfg, model="prior", lr=personalizing_lr(cfg)), prior, gl,
                                               on_frame=reading)
    last = run_trainer(trainer, gl)
    if last is None:
        return 0
    print(f"wrote {cfg.out}: {trainer.step} steps in {trainer.elapsed / 60:.1f} min, "
          f"last loss {last.get('loss', 0):.5f}")
    print_next(cfg)
    return 0


def personalizing_lr(cfg: TrainConfig) -> float:
    """The learning rate a personalisation runs at: the prior's (PERSONALIZE_LR) unless --lr says otherwise."""
    return PERSONALIZE_LR if cfg.lr == TrainConfig.lr else cfg.lr


def print_next(cfg: TrainConfig) -> None:
    out, dataset = shlex.quote(str(cfg.out)), shlex.quote(str(cfg.dataset))
    print(f"next: avatar-studio studio {out}  (or: avatar-studio turntable {out}; avatar-studio eval {out} {dataset})")


def run_trainer(trainer, gl: GLContext, on_record=None, choose_codes: bool = True) -> dict | None:
    """Run a trainer to its budget, its progress on the terminal (and to on_record), then (choose_codes) choose how
    its video's frames no one trained on take their codes; its last record, or None where it was stopped (SIGTERM,
    the studio's Cancel, or Ctrl-C: it finishes the step and checkpoints)."""
    tty = sys.stderr.isatty()
    last_line = [0.0]

    def show(r: dict) -> None:
        """On a terminal a line redrawn at every log record (every 50 steps, and every PROGRESS_SECONDS); in a log
        a line at most that often (and at validation). The photometric error apart from the weighted total, which
        rises when a term joins mid-run."""
        if on_record is not None:
            on_record(r)
        text = (f"step {r['step']}" + (f"  photometric {r['photometric']:.5f}" if "photometric" in r else "")
                + f"  total {r['loss']:.5f}  {r['elapsed_s']:.0f} s, {r['eta_s']:.0f} s left"
                + (f"  val PSNR {r['val_psnr']:.2f} dB" if "val_psnr" in r else ""))
        if tty:
            sys.stderr.write(f"\r{text}   ")
        elif r["elapsed_s"] - last_line[0] >= PROGRESS_SECONDS or r["step"] == 1 or "val_psnr" in r:
            last_line[0] = r["elapsed_s"]
            sys.stderr.write(text + "\n")
        sys.stderr.flush()

    def stop(signum, frame) -> None:
        """SIGTERM (the studio's Cancel) and Ctrl-C: finish the step, checkpoint, exit; a second Ctrl-C aborts."""
        if trainer.stop_requested and signum == signal.SIGINT:
            raise KeyboardInterrupt
        trainer.stop_requested = True
        if signum == signal.SIGINT:
            sys.stderr.write("\nstopping after this step with a checkpoint (Ctrl-C again to abort)\n")

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    last = trainer.run(gl, show)
    if tty:
        sys.stderr.write("\n")
    if trainer.stop_requested:
        print(f"stopped at step {trainer.step}; checkpoint in {trainer.cfg.out} (continue with --resume)")
        return None
    if choose_codes:
        choose_code_time_aloud(trainer, gl)
    return last


def choose_code_time_aloud(trainer, gl: GLContext) -> None:
    """After a tracked video's training: how the video's own frames that no one trained on take their codes
    (Trainer.choose_code_time), said in a line, with a bar while its renders run; the avatar saved with it."""
    bars: list[Progress] = []

    def on_frame(done: int, total: int) -> None:
        if not bars:
            bars.append(Progress("choosing the codes of frames no one trained on", total, "renders"))
        bars[0].update(done)

    choice = trainer.choose_code_time(gl, on_frame)
    if choice is None:
        return
    trainer.save()
    if not choice["frames"]:
        print("frames of the video no one trained on take the codes of the training frames nearest in controls "
              "(no validation frame came late enough to choose)", flush=True)
        return
    way = "controls and time" if choice["by_time"] else "controls"
    print(f"frames of the video no one trained on take the codes of the training frames nearest in {way}: on "
          f"{choice['frames']} validation frames, from earlier frames' codes, {choice['psnr_controls_and_time']:.2f} "
          f"dB by controls and time against {choice['psnr_controls']:.2f} by controls", flush=True)


WHOLE_PARTS = "parts"
"""Where a whole head's two parts train, inside its folder (parts/inside, parts/outside): each its own checkpoint,
so that `train --resume` continues the one that was stopped."""
WHOLE_PRIOR_NOTE = "prior.json"
"""In WHOLE_PARTS: the prior the outside personalises (named when the training began)."""
WHOLE_OUTSIDE_SHARE = 0.1
"""The share of a whole head's budget (minutes, steps) that personalises the prior: 3 of 30 minutes. Measured
(docs/results.md): 3 minutes keep the prior's whole head, 30 lose it."""


WHOLE_OUTSIDE_TUNE = "texel"
"""What personalising the prior fine-tunes for a whole head's outside: the decoder's per-texel bias maps alone, so
that whatever no frame of the video saw (the sides and back) stays as the prior decodes it. Fine-tuning every weight
made the sides of real heads a patchwork of boxes of hair and skin (docs/results.md "What personalising does beyond
the views"); the inside shows what the video saw."""


def budget_share(budget: float | int | None, share: float) -> float | int | None:
    """A share of a budget: minutes as they are, steps whole and at least one; None stays None.

    >>> budget_share(30.0, 0.1), budget_share(2000, 0.9), budget_share(5, 0.1), budget_share(None, 0.5)
    (3.0, 1800, 1, None)
    """
    if budget is None:
        return None
    return max(1, round(budget * share)) if isinstance(budget, int) else budget * share


def train_whole(cfg: TrainConfig, gl: GLContext, prior: Path | None) -> int:
    """A whole-head avatar (models/avatars/whole/): the video's avatar from scratch (`inside`), then the universal
    prior personalised on the same video (`outside`), each in its folder under WHOLE_PARTS, then both put together
    in cfg.out. `--resume` continues each part to its share of the budget given (the one that was stopped, or both
    of a finished whole head given more) and puts them together again. The studio's job reads the two runs'
    progress as one (cfg.out's progress.jsonl, the outside's steps and seconds after the inside's)."""
    parts = cfg.out / WHOLE_PARTS
    inside_cfg = replace(cfg, out=parts / "inside", model="primitives", prior=None,
                         minutes=budget_share(cfg.minutes, 1 - WHOLE_OUTSIDE_SHARE),
                         steps=budget_share(cfg.steps, 1 - WHOLE_OUTSIDE_SHARE),
                         resume=(parts / "inside" / "avatar.json").is_file())
    # --lr is the inside's (from scratch): the prior's personalisation keeps its own rate (given --lr 0.01 too, its
    # validation fell to 11.4 and 24.7 dB on two clips in 10 minutes, from 28.6 and 27.5, where the inside gained)
    outside_cfg = replace(cfg, out=parts / "outside", model="prior", lr=PERSONALIZE_LR,
                          minutes=budget_share(cfg.minutes, WHOLE_OUTSIDE_SHARE),
                          steps=budget_share(cfg.steps, WHOLE_OUTSIDE_SHARE),
                          resume=(parts / "outside" / "avatar.json").is_file())
    if cfg.minutes is None and cfg.steps is None:  # the trainer's own default, shared the same way
        inside_cfg = replace(inside_cfg, steps=budget_share(DEFAULT_STEPS, 1 - WHOLE_OUTSIDE_SHARE))
        outside_cfg = replace(outside_cfg, steps=budget_share(DEFAULT_STEPS, WHOLE_OUTSIDE_SHARE))
    log = cfg.out / "progress.jsonl"
    before = {"step": 0, "elapsed_s": 0.0}

    def mirror(stage: str):
        def on_record(r: dict) -> None:
            record = {**r, "stage": stage, "step": r["step"] + before["step"],
                      "elapsed_s": r["elapsed_s"] + before["elapsed_s"]}
            with open(log, "a") as f:
                f.write(json.dumps(record) + "\n")
        return on_record

    if prior is not None:  # the prior this whole head personalises, for a --resume before its turn comes
        parts.mkdir(parents=True, exist_ok=True)
        (parts / WHOLE_PRIOR_NOTE).write_text(json.dumps({"prior": str(Path(prior).resolve())}) + "\n")
    reading = progress_by_stage()  # the inside's frames, then the outside's: a bar for each
    print(f"training the inside ({inside_cfg.out}: from scratch{', continued' if inside_cfg.resume else ''})",
          flush=True)
    inside = prepare_training(inside_cfg, gl, on_frame=reading)
    if run_trainer(inside, gl, mirror("inside")) is None:
        return 0
    before.update(step=inside.step, elapsed_s=inside.elapsed)
    if outside_cfg.resume:
        outside = prepare_training(outside_cfg, gl, on_frame=reading)
    else:
        if prior is None:  # resumed before the outside began: the prior the first run named
            noted = parts / WHOLE_PRIOR_NOTE
            try:
                split = load_split(cfg.dataset, "train")
                named = cfg.prior or (Path(json.loads(noted.read_text())["prior"]) if noted.is_file() else None)
                _, prior, _ = training_start(split.head_model, split.tracked, "whole", False, named)
            except CheckpointError as e:
                raise UserInputError(str(e)) from None
            except (OSError, ValueError, KeyError, TypeError) as e:
                raise UserInputError(f"{noted}: cannot read the prior the training began with ({e})") from None
        print(f"training the outside ({outside_cfg.out}: the universal prior {prior} personalised)", flush=True)
        outside, _ = personalizing_trainer(outside_cfg, prior, gl, WHOLE_OUTSIDE_TUNE, on_frame=reading)
    # (a whole head's codes are its inside's: WholeHeadAvatar.code_keys)
    if run_trainer(outside, gl, mirror("outside"), choose_codes=False) is None:
        return 0
    try:
        compose(inside_cfg.out, outside_cfg.out, cfg.out)
    except CheckpointError as e:
        raise UserInputError(str(e)) from None
    print(f"wrote {cfg.out}: a whole head, {inside.step} steps from scratch and {outside.step} personalising the "
          f"prior in {(inside.elapsed + outside.elapsed) / 60:.1f} min")
    print_next(cfg)
    return 0


def face_mask_of(frame, image_shape) -> np.ndarray:
    """Pixels of the face: the capture's mask inside its landmark box (the whole mask if no box)."""
    h, w = image_shape[:2]
    if "mask_path" in frame.extra:
        mask = load_rgb(frame.extra["mask_path"])[..., 0] > 0.5
    else:
        mask = np.ones((h, w), bool)
    if frame.bbox is not None:
        top, bottom, left, right = frame.bbox
        box = np.zeros((h, w), bool)
        box[int(top * h):int(np.ceil(bottom * h)), int(left * w):int(np.ceil(right * w))] = True
        mask &= box
    return mask


SHADOW_METRICS = ("shadow_corr", "unshadowed_psnr", "unshadowed_psnr_render")


def shadow_metrics(avatar, frame, split, raster, truth: np.ndarray, on: np.ndarray, row: dict) -> list[np.ndarray]:
    """The avatar's cast shadows against a synthetic capture's truth, into `row`: shadow_corr, the correlation
    over the head (`on`) of the light the shadows take away (luminance without them - with them) with the
    share of the key light blocked; and where the capture has the frame without cast shadows, PSNR over the
    head of the render without them against it (unshadowed_psnr) and, for scale, of the render itself
    (unshadowed_psnr_render: what doing nothing scores). Returns the panels: without shadows, the shadows x4."""
    out = render_image(avatar, frame_camera(split, frame), frame.controls, RenderOptions(inspect=True), raster)
    taken = luminance(out["rgb_no_shadows"]) - luminance(out["rgb"])
    gt = load_rgb(frame.extra["shadow_path"])[..., 0]
    if on.any():
        row["shadow_corr"] = pearson(taken, gt, on)
    if "unshadowed_path" in frame.extra and on.any():
        lit = load_rgb(frame.extra["unshadowed_path"], avatar.background_colour())
        row["unshadowed_psnr"] = psnr(out["rgb_no_shadows"], lit, on)
        row["unshadowed_psnr_render"] = psnr(out["rgb"], lit, on)
    return [out["rgb_no_shadows"], np.repeat(np.clip(taken * 4, 0, 1)[..., None], 3, -1)]


def run_eval(cfg: EvalConfig) -> int:
    foreign = foreign_files(cfg.out, r"metrics\.json|(train|val|test)_\d{4}\.png")
    if foreign:
        raise UserInputError(f"{cfg.out}: holds files eval did not write ({foreign[0].name}...); choose another --out")
    avatar, meta = open_avatar(cfg.avatar, cfg.device)
    split = load_split(cfg.dataset, cfg.split)
    check_images(split)
    mismatch = capture_mismatch(avatar.head_model, meta, split)
    if mismatch:  # measured all the same: a stranger's capture is a fair question, only not the usual one
        print(f"avatar-studio eval: warning: {cfg.dataset}: {mismatch}; the metrics measure the avatar on it all the "
              "same", file=sys.stderr)
    own = own_capture(meta, cfg.dataset)  # its frames' times mean something to the avatar's codes
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    cfg.out.mkdir(parents=True, exist_ok=True)
    rows, times = [], []
    shadow_views = avatar.inspection_buffers()
    frames = split.frames[:: max(cfg.every, 1)]
    frames = frames[: cfg.max_frames] if cfg.max_frames else frames
    bar, background = Progress(f"rendering the {cfg.split} frames", len(frames)), avatar.background_colour()
    for k, f in enumerate(frames):
        truth = load_rgb(f.image_path, background)
        t0 = time.perf_counter()
        out = render_image(avatar, frame_camera(split, f), f.controls,
                           RenderOptions(room=frame_room(f), time_s=f.time_s if own else None), rasterizer=raster)
        times.append(time.perf_counter() - t0)
        face = face_mask_of(f, truth.shape)
        dx, dy = image_offset_px(out["rgb"], truth)
        row = {"frame": f.index, "psnr": psnr(out["rgb"], truth), "ssim": ssim(out["rgb"], truth),
               "face_mse": face_mse(out["rgb"], truth, face), "offset_px": float(np.hypot(dx, dy)),
               "offset_xy_px": [round(dx, 2), round(dy, 2)]}
        if "mask_path" in f.extra:  # the person alone: where a frame's own room stands behind it, the rest is exact
            person = load_mask(f.extra["mask_path"]) > 0.5
            if person.any():
                row["psnr_person"] = psnr(out["rgb"], truth, person)
        panels = [truth, out["rgb"], np.clip(np.abs(out["rgb"] - truth) * 4, 0, 1)]
        if "normals" in out:
            panels.append(out["normals"] * 0.5 + 0.5)
            if "normal_path" in f.extra:
                gt_n = read_png16(f.extra["normal_path"]) * 2 - 1
                on = face & (out["opacity"] > 0.5)
                if on.any():
                    angles = normal_angles_deg(out["normals"], gt_n, on)
                    row["normal_deg"], row["normal_median_deg"] = float(angles.mean()), float(np.median(angles))
        if "rgb_no_shadows" in shadow_views and "shadow_path" in f.extra:
            panels += shadow_metrics(avatar, f, split, raster, truth, face & (out["opacity"] > 0.5), row)
        rows.append(row)
        save_png(cfg.out / f"{cfg.split}_{f.index:04d}.png",
                 (np.concatenate(panels, 1) * 255).round().astype(np.uint8))
        bar.update(k + 1)
    metrics = {k: float(np.mean([r[k] for r in rows if k in r])) for k in (
        "psnr", "psnr_person", "ssim", "face_mse", "offset_px", "normal_deg", "normal_median_deg", *SHADOW_METRICS)
        if any(k in r for r in rows)}
    metrics["render_ms"] = 1e3 * float(np.median(times))
    report = {"avatar": str(cfg.avatar), "dataset": str(cfg.dataset), "split": cfg.split, "frames": len(rows),
              "effects": meta.get("effects"), "training": meta.get("provenance"),
              "codes_by_time": own and avatar.code_keys.keys_time, "metrics": metrics, "per_frame": rows}
    (cfg.out / "metrics.json").write_text(json.dumps(report, indent=1))
    images = f"{len(rows)} side-by-side image{'s' * (len(rows) != 1)} ({cfg.out / cfg.split}_NNNN.png"
    print(f"wrote {cfg.out / 'metrics.json'} and {images}: truth, render, error x4...); PSNR {metrics['psnr']:.2f} "
          f"dB, SSIM {metrics['ssim']:.3f}, face MSE {metrics['face_mse']:.4f}, {metrics['offset_px']:.1f} px from the "
          f"truth, {metrics['render_ms']:.0f} ms a frame")
    return 0


IDENTITY_GAP_M = 0.0025
"""Identity shapes that move some vertex of the head model further apart than this are two people's. Measured with
the built-in head on 2-second clips (64 px): one person tracked twice 0.6 to 1.1 mm apart, the three people of
../shared/data/video 3.8 to 5.6 mm; synthetic identities (synth --identity) 9 to 30 mm."""


def own_capture(meta: dict, folder: Path) -> bool:
    """Whether a capture is the one the avatar trained on (avatar.json's provenance): its frames' times in the
    video are the times its codes know (components/codes.py)."""
    trained_on = meta.get("provenance", {}).get("dataset_resolved")
    return trained_on is not None and Path(trained_on) == Path(folder).resolve()


def capture_mismatch(model, meta: dict, split) -> str | None:
    """Why a capture is not of the avatar's kind, or None: tracked with another head model than the avatar's (its
    controls mean other things), or of another person (their identity shapes, the head model's coefficients, move
    some vertex more than IDENTITY_GAP_M apart). Avatars that recorded no shape are compared by head model only."""
    def spec(s) -> str:
        kind, _, path = str(s or "").partition(":")
        return f"{kind}:{Path(path).resolve()}" if path else kind

    if spec(split.head_model) != spec(meta.get("head_model")):
        return (f"tracked with the head model {split.head_model}, the avatar with {meta.get('head_model')} (its "
                "controls mean other things to this avatar)")
    if not isinstance(meta.get("shape"), list) or split.head_model is None:
        return None
    S = model.num_shape
    a, b = (np.pad(x[:S], (0, S - len(x[:S]))) for x in (np.ravel(meta["shape"]).astype(float),
                                                          np.ravel(split.shape).astype(float)))
    gap = float(np.linalg.norm(np.asarray(model.shape_basis) @ (a - b), axis=-1).max())  # (V,3,S) @ (S,): metres
    if gap > IDENTITY_GAP_M:
        return (f"of another person than the avatar's (their identity shapes move the head up to {1e3 * gap:.0f} mm "
                "apart)")
    return None


def run_render(cfg: RenderCommandConfig) -> int:
    avatar, _ = open_avatar(cfg.avatar, cfg.device)
    controls = avatar.card.at_rest(load_controls(cfg.controls, avatar.head_model) if cfg.controls else Controls())
    buffers, inspect = render_needs(cfg.buffer)
    options, size = preset_options(avatar.card, cfg.preset, cfg.size, RenderOptions(inspect=inspect, buffers=buffers))
    cam = framing_camera(avatar.card.rest_vertices(), cfg.yaw_deg, cfg.pitch_deg, fov_y_deg=18.0, width_px=size,
                         height_px=size)
    offered = avatar.inspection_buffers()
    if cfg.buffer in INSPECT and INSPECT[cfg.buffer] not in offered:
        why = "; it has no shadow factor (its capture recorded no key light, or it was trained before the factor " \
              "existed)" if cfg.buffer == "rgb_light" and "rgb_no_shadows" in offered else ""
        raise UserInputError(f"--buffer {cfg.buffer}: {cfg.avatar} ({avatar.name}, effects: "
                             f"{avatar.describe_effects()}) has no such buffer{why}")
    gl = GLContext.headless()
    t0 = time.perf_counter()
    out = render_image(avatar, cam, controls, options, Rasterizer(gl))
    ms = 1e3 * (time.perf_counter() - t0)
    if cfg.buffer not in out and cfg.buffer not in INSPECT:
        raise UserInputError(f"--buffer {cfg.buffer}: this avatar's effect set has no normals network")
    cfg.out.parent.mkdir(parents=True, exist_ok=True)
    save_png(cfg.out, resized(buffer_image(out, cfg.buffer), cfg.size))
    scaled = f", rendered at {size}x{size}" if size != cfg.size else ""
    print(f"wrote {cfg.out} ({cfg.size}x{cfg.size}, {cfg.buffer}, {cfg.preset}{scaled}: {ms:.0f} ms)")
    return 0


def run_turntable(cfg: TurntableConfig) -> int:
    avatar, _ = open_avatar(cfg.avatar)
    if cfg.frames < 1 or cfg.size < 8:
        raise UserInputError(f"--frames {cfg.frames} --size {cfg.size}: need at least 1 frame of 8 pixels")
    check_video_size(cfg.size)
    if cfg.out.suffix.lower() != ".mp4":
        raise UserInputError(f"{cfg.out}: the turntable is written as an .mp4")
    gl = GLContext.headless()
    pngs = frames_folder(cfg.out, cfg.pngs, "turntable")
    t0 = time.perf_counter()
    bar = Progress("turntable", cfg.frames)
    n = write_video(turntable_frames(avatar, Rasterizer(gl), cfg, on_frame=lambda k: bar.update(k + 1)), cfg.out,
                    cfg.fps, pngs)
    print(f"wrote {cfg.out} ({n} frames{f', PNGs in {pngs}' if pngs else ''}) in {time.perf_counter() - t0:.1f} s")
    return 0


def run_prior_train(cfg: PriorTrainConfig) -> int:
    """`prior-train`: the universal prior on a corpus, in this process or, under torchrun, in every process it
    starts (rank 0 writes the folder and the progress lines)."""
    device_of(cfg.device)
    try:
        parse_effects(cfg.effects)
        corpus_folders(cfg.corpus, cfg.people)
    except (ValueError, FileNotFoundError) as e:
        raise UserInputError(str(e)) from None
    if not cfg.resume and (cfg.out / "avatar.json").exists():
        raise UserInputError(f"{cfg.out}: already holds a prior; pass --resume to continue it or choose a new folder")
    rank, world = distributed_from_env(cfg.device)
    gl = GLContext.headless()
    reading = progress_callback("reading the corpus", "identities") if rank == 0 else None
    trainer = prepare_prior(cfg, gl, rank, world, reading)

    def show(r: dict) -> None:
        sys.stderr.write(f"step {r['step']}  loss {r['loss']:.5f}  {r['elapsed_s']:.0f} s\n")

    last = trainer.run(show if rank == 0 else None)
    if rank == 0:
        print(f"wrote {cfg.out}: {trainer.step} steps over {len(trainer.identities)} identities in "
              f"{trainer.elapsed / 60:.1f} min on {world} process(es), last loss {last.get('loss', 0):.5f}")
    return 0


def run_personalize(cfg: PersonalizeConfig) -> int:
    """`personalize`: the prior's avatar of one person: the neutral maps from the scan (the head model's fitted shape,
    the colours of its least expressive frames unprojected), the identity encoder's bias maps from them, then
    fine-tuning on the scan's frames. The result is an ordinary avatar folder."""
    device_of(cfg.device)
    if cfg.out.exists() and (not cfg.out.is_dir() or any(cfg.out.iterdir())):
        raise UserInputError(f"{cfg.out}: already exists and is not empty; choose a new folder")
    tcfg = TrainConfig(dataset=cfg.scan, out=cfg.out, model="prior", minutes=cfg.minutes or None,
                       steps=cfg.steps or (None if cfg.minutes else 1), device=cfg.device, seed=cfg.seed, lr=cfg.lr)
    gl = GLContext.headless()
    trainer, maps_s = personalizing_trainer(tcfg, cfg.prior, gl, cfg.tune, on_frame=progress_by_stage())
    if cfg.minutes or cfg.steps:
        trainer.run(gl)
    else:
        trainer.save()
    print(f"wrote {cfg.out}: maps in {maps_s:.1f} s, then {trainer.step} fine-tuning steps in "
          f"{trainer.elapsed / 60:.1f} min ({cfg.tune}, lr {cfg.lr:g}) from the prior {cfg.prior}")
    print(f"next: avatar-studio studio {shlex.quote(str(cfg.out))}")
    return 0


def personalizing_trainer(tcfg: TrainConfig, prior: Path, gl: GLContext, tune: str = "all", on_frame=None):
    """The trainer that fine-tunes a copy of the universal prior in `prior` on the capture tcfg.dataset (its
    neutral maps made first: the head model's fitted shape, the colours of its least expressive frames), and the
    seconds the maps took. `personalize` runs it, and `train` where it starts from the prior."""
    from models.training.data import validation_frame
    from models.training.prior import neutral_texture
    from models.training.trainer import Trainer, capture_frames

    split = load_split(tcfg.dataset, "train")
    check_images(split)
    try:
        avatar, _ = load_prior(prior, split.head_model, tcfg.device)
    except CheckpointError as e:
        raise UserInputError(str(e)) from None
    t0 = time.perf_counter()
    plate = background_plate(split)  # a tracked video's room: composited behind the person, as `train` does
    with torch.no_grad():
        bg = split.background if plate is None else plate[0].reshape(-1, 3).mean(0)
        avatar.background.copy_(torch.as_tensor(np.asarray(bg, np.float32)))
        if plate is not None:
            avatar.plate.note(*plate, avatar.background.device)
        shape = split.frames[0].controls.shape
        avatar.personalize(neutral_texture(split, avatar, gl), avatar.neutral_geometry_of(shape))
    avatar.tune_only(tune)
    maps_s = time.perf_counter() - t0
    avatar.train()
    frames = capture_frames(avatar, split, gl, on_frame=on_frame)
    val = load_split(tcfg.dataset, "val")
    validation = validation_frame(val, avatar.background_colour()) if val.frames else None
    trainer = Trainer(tcfg, avatar, frames, validation, val_split=val)
    return trainer, maps_s


def check_video_size(size: int) -> None:
    """An odd --size refused before any work: H.264 (yuv420p) frames have even sides."""
    if size % 2:
        raise UserInputError(f"--size {size}: an H.264 video's frames need an even number of pixels (try {size + 1})")


def frames_folder(out: Path, wanted: bool, what: str) -> Path | None:
    """Where a video's PNG frames go (the mp4's name without its suffix), or None; a folder that holds other files
    is refused before any work."""
    pngs = out.with_suffix("") if wanted else None
    if pngs is not None and (pngs.is_file() or foreign_files(pngs, r"frame_\d{4}\.png")):
        raise UserInputError(f"{pngs}: the {what}'s PNG frames go there, and it holds other files; choose another "
                             "--out or pass --no-pngs")
    return pngs


def guide_mesh_writer(avatar, out: Path, kind: str):
    """on_pose(k, controls) for animation_frames: the posed guide mesh of frame k to OUT_meshes/frame_K.obj|ply
    (nothing for kind "none"); a folder that holds other files is refused first."""
    meshes = out.with_name(out.stem + "_meshes") if kind != "none" else None
    if meshes is not None and (meshes.is_file() or foreign_files(meshes, r"frame_\d{4}\.(obj|ply)")):
        raise UserInputError(f"{meshes}: the guide meshes go there, and it holds other files; choose another --out")

    def write_mesh(k: int, controls: Controls) -> None:
        from models.head.meshio import mesh_bytes

        if meshes is None:
            return
        meshes.mkdir(parents=True, exist_ok=True)
        with torch.no_grad():
            verts = avatar.head.pose([controls])[0][0].cpu().numpy()
        atomic_write_bytes(meshes / f"frame_{k:04d}.{kind}", mesh_bytes(f".{kind}", verts, avatar.head_model.triangles))

    return write_mesh


def run_animate(cfg: AnimateConfig) -> int:
    from app.animation import AnimationError, animation_frames, check_channels, load_animation

    avatar, _ = open_avatar(cfg.avatar)
    try:
        anim = load_animation(cfg.animation)
        check_channels(anim, avatar.head_model, str(cfg.animation))
    except AnimationError as e:
        raise UserInputError(str(e)) from None
    if cfg.out.suffix.lower() != ".mp4":
        raise UserInputError(f"{cfg.out}: the animation is written as an .mp4")
    check_video_size(cfg.size)
    pngs = frames_folder(cfg.out, cfg.pngs, "animation")
    write_mesh = guide_mesh_writer(avatar, cfg.out, cfg.meshes)

    gl = GLContext.headless()
    t0 = time.perf_counter()
    bar = Progress("animate", anim.frames)
    n = write_video(animation_frames(avatar, Rasterizer(gl), anim, cfg.size, cfg.preset,
                                     on_frame=lambda k: bar.update(k + 1), on_pose=write_mesh), cfg.out, anim.fps,
                    pngs)
    seconds = time.perf_counter() - t0
    print(f"wrote {cfg.out} ({n} frames at {anim.fps:g} fps{f', PNGs in {pngs}' if pngs else ''}) in {seconds:.1f} s "
          f"({1e3 * seconds / max(n, 1):.0f} ms a frame, {cfg.preset})")
    return 0


def run_export_mesh(cfg: ExportMeshConfig) -> int:
    """`export-mesh`: the avatar as a coloured mesh (models/avatars/mesh.py)."""
    from app.head_commands import _check_out
    from models.avatars.mesh import avatar_mesh
    from models.head.meshio import mesh_bytes

    _check_out(cfg.out, (".obj", ".ply"))
    avatar, _ = open_avatar(cfg.avatar)
    controls = load_controls(cfg.controls, avatar.head_model) if cfg.controls else None
    t0 = time.perf_counter()
    try:
        raster = Rasterizer(GLContext.headless())
        verts, tris, colours, level = avatar_mesh(avatar, controls, cfg.resolution, cfg.level, raster)
    except ValueError as e:
        raise UserInputError(f"{cfg.avatar}: {e}") from None
    atomic_write_bytes(cfg.out, mesh_bytes(cfg.out.suffix, verts, tris, colours))
    print(f"wrote {cfg.out} ({len(verts)} vertices, {len(tris)} triangles, {cfg.out.stat().st_size / 1e6:.1f} MB) in "
          f"{time.perf_counter() - t0:.1f} s; the surface where the density is {level:.1f} per metre")
    return 0
