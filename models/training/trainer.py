"""Training an avatar on a capture: batches of rays from random frames, the losses of Eq. 9-14, Adam,
crash-safe checkpoints, exact resume, and a progress log the studio can read."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

from models.avatars.base import Avatar, TrainingBatch
from models.avatars.checkpoint import Checkpoint, CheckpointError, load_checkpoint, save_checkpoint
from models.avatars.components.codes import TIME_SCALE_S
from models.avatars.effects import parse_effects
from models.avatars.registry import DEFAULT_MODEL, avatar_class, default_model
from models.avatars.rendering import RenderOptions, render_image
from models.capture.dataset import CaptureSplit, DatasetError, check_images, load_split
from models.capture.frames import background_plate, view_range
from models.device import device_of
from models.files import atomic_write_bytes
from models.head.sources import load_head
from models.ranges import OptionError, config_with
from models.training.configs import TrainConfig
from models.training.data import FrameSet, ValidationFrame, build_frames, validation_frame
from models.training.metrics import psnr
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

DEFAULT_STEPS = 2000
"""The step budget of a run given neither minutes nor steps (TrainConfig.steps)."""


def _adam_state_tensors(opt: torch.optim.Adam) -> dict[str, torch.Tensor]:
    out = {}
    for i, (p, st) in enumerate((p, opt.state[p]) for g in opt.param_groups for p in g["params"]):
        del p
        for k, v in st.items():
            out[f"adam.{i}.{k}"] = v if torch.is_tensor(v) else torch.tensor(v)
    return out


def _load_adam_state(opt: torch.optim.Adam, tensors: dict[str, torch.Tensor]) -> None:
    for i, p in enumerate(p for g in opt.param_groups for p in g["params"]):
        st = {k.split(".", 2)[2]: v for k, v in tensors.items() if k.startswith(f"adam.{i}.")}
        if st:
            # Adam keeps its step count on the CPU, its moments beside the parameter.
            opt.state[p] = {k: v.clone() if k == "step" else v.to(p.device) for k, v in st.items()}


def prepare_training(cfg: TrainConfig, gl: GLContext, model_config: Any = None,
                     on_frame: Callable[[str, int, int], None] | None = None) -> Trainer:
    """A training run from its config: read the capture and the head model (and the checkpoint to resume), build
    the avatar the registry names, read and rasterize the frames. model_config: the model's own sizes or loss
    weights (its for_capture's `config`; None: its defaults). on_frame(stage, done, total): as the frames are read
    and placed (build_frames)."""
    split, val_split = load_split(cfg.dataset, "train"), load_split(cfg.dataset, "val")
    for s in (split, val_split):  # a truncated or wrong-size image: a clear error before any work
        check_images(s)
    if not split.trains_codynerf:
        raise DatasetError(f"{cfg.dataset}: the capture has no head model tracked on its frames; "
                           "every avatar here reads the head's pose and expression from it")
    head = load_head(split.head_model)
    plate = background_plate(split)
    bg = split.background if plate is None else plate[0].reshape(-1, 3).mean(0)
    torch.manual_seed(cfg.seed)
    resumed = load_checkpoint(cfg.out, with_train_state=True) if cfg.resume else None
    if resumed is not None:  # the checkpoint's own model and sizes (an older one: no shadow factor)
        cls = avatar_class(resumed.meta.get("model", DEFAULT_MODEL))
        if cfg.model_options:
            raise CheckpointError(f"{cfg.out}: --model-options with --resume; the avatar keeps the settings it was "
                                  "trained with (avatar.json)")
        avatar = cls.from_meta(head, resumed.meta)
        if cfg.effects is not None and set(parse_effects(cfg.effects)) != set(avatar.effects):
            raise CheckpointError(f"{cfg.out}: --effects {cfg.effects} with --resume, but the avatar was trained with "
                                  f"{avatar.describe_effects()}; leave --effects out to continue it")
    else:
        model = cfg.model or default_model(split.tracked)
        model_config = model_config or avatar_class(model).default_config(split.tracked)
        if cfg.model_options:
            model_config = model_options(avatar_class(model), cfg.model_options, model_config)
        avatar = avatar_class(model).for_capture(head, len(split.frames), bg, parse_effects(cfg.effects or "all"),
                                                     split.lighting, model_config)
        if plate is not None:
            avatar.plate.note(*plate)
    frames = capture_frames(avatar, split, gl, cfg.corrections, on_frame)
    validation = validation_frame(val_split, avatar.background_colour()) if val_split.frames else None
    return Trainer(cfg, avatar, frames, validation, resumed, val_split)


def capture_frames(avatar: Avatar, split, gl: GLContext, corrections: bool | None = None,
                   on_frame: Callable[[str, int, int], None] | None = None) -> FrameSet:
    """The training frames of a capture, the avatar made ready for them: a tracked video's corrections and code
    keys, what the frames saw (note_views). Every avatar `train` makes or resumes, and a personalised prior."""
    if split.tracked:  # (a resumed avatar too: what it learns is not all in avatar.json)
        avatar.fit_to_tracked_video(corrections)
        # Its codes carry what the controls miss (hair, shoulders) and follow the controls: held-out frames and
        # sliders take the nearest training frames' (components/codes.py). Synthetic captures keep the mean code.
        avatar.code_keys.note([f.controls for f in split.frames], [f.time_s for f in split.frames])
    frames = build_frames(split, avatar, gl, on_frame)
    avatar.note_views(frames)
    return frames


def model_options(cls: type[Avatar], settings: tuple[str, ...], base: Any) -> Any:
    """`--model-options` over the config a new avatar would get (base; None: the model's defaults)."""
    if cls.config_class is None:
        raise OptionError(f"--model-options: {cls.name} avatars have no settings")
    return config_with(cls.config_class, settings, base)


def trim_progress(log: Path, step: int) -> None:
    """Drop the records after `step` (a run resumed from its checkpoint logs those steps again), and a last line
    cut short by a kill."""
    if not log.exists():
        return
    kept = []
    for line in log.read_text().splitlines():
        try:
            if json.loads(line)["step"] <= step:
                kept.append(line)
        except (json.JSONDecodeError, KeyError, TypeError):
            continue
    atomic_write_bytes(log, "".join(x + "\n" for x in kept).encode())


PROGRESS_SECONDS = 5.0
"""A progress record at least this often (besides every 50 steps): a capture's steps can take seconds each."""


class Trainer:
    """A training run; its state (step, weights, optimiser, sampler) is a value that can be saved and resumed.
    Built from data (prepare_training reads the files)."""

    def __init__(self, cfg: TrainConfig, avatar: Avatar, frames: FrameSet, validation: ValidationFrame | None = None,
                 resumed: Checkpoint | None = None, val_split: CaptureSplit | None = None):
        self.cfg = cfg
        self.avatar = avatar
        self.frames = frames
        self.split = frames.split
        self.validation = validation
        self.val_split = val_split
        """The validation frames that choose how new frames of the video take their codes (choose_code_time)."""
        self.code_choice: dict | None = None
        """That choice and its measure, for avatar.json (`held_out_codes`)."""
        template = avatar.head_model.template
        self.view_range = view_range(frames.split, 0.5 * (template.min(0) + template.max(0)))
        if avatar.all_round:  # a person's prior, or a whole head: its prior saw heads from every side (its corpus's
            self.view_range["yaw_deg"] = [-180.0, 180.0]  # cameras go round them): turntables and orbits go round
        self.rest_translation = np.mean([f.controls.translation for f in frames.split.frames], 0) \
            if frames.split.frames else np.zeros(3)
        self.rays_per_step = cfg.rays_per_step or avatar.rays_per_step
        self.frames_per_step = cfg.frames_per_step or avatar.frames_per_step
        # The networks and each frame's geometry go to the device; images, rays, the k-d trees and the random
        # generator (its state is part of the checkpoint) stay on the CPU, and each step's rays are moved over.
        self.device = device_of(cfg.device)
        self.avatar.to(self.device)
        self.frames.geometry = [geo.to(self.device) for geo in self.frames.geometry]
        self.opt = torch.optim.Adam(self.avatar.parameter_groups(), lr=cfg.lr)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.step = 0
        self.skipped_steps = 0
        """Steps whose loss or gradient was not finite: the weights were left as they were (optimiser_step)."""
        self.elapsed = 0.0
        self.stop_requested = False
        """Set (from a signal handler) to end the run after the current step, with a checkpoint."""
        if resumed is not None:
            self._resume(resumed)

    # ---- state -----------------------------------------------------------------------------------------
    def meta(self) -> dict:
        return {**self.avatar.meta(), "head_model": self.split.head_model,
                "shape": [round(float(v), 5) for v in np.ravel(self.split.shape)],  # whose head: eval compares
                "frames": len(self.split.frames),
                "image_px": [self.split.width, self.split.height], "view_range": self.view_range,
                "rest_pose": {"translation": [round(float(v), 5) for v in self.rest_translation]},
                "background": self.avatar.background.tolist(),
                "provenance": {"dataset": str(self.cfg.dataset),
                               "dataset_resolved": str(Path(self.cfg.dataset).resolve()), "steps": self.step,
                               "skipped_steps": self.skipped_steps, "frames_per_step": self.frames_per_step,
                               "seconds": round(self.elapsed, 1), "config": {k: str(v) for k, v in
                                                                            asdict(self.cfg).items()}},
                **({"held_out_codes": self.code_choice} if self.code_choice is not None else {})}

    def save(self) -> None:
        self.avatar.before_save(self.frames.geometry[0])
        state = _adam_state_tensors(self.opt)
        state["generator"] = self.generator.get_state()
        state["elapsed"] = torch.tensor(self.elapsed, dtype=torch.float64)
        save_checkpoint(self.cfg.out, self.meta(), self.avatar.state_dict(), self.step, state)

    def _resume(self, ck: Checkpoint) -> None:
        self.avatar.load_state_dict(ck.weights)
        _load_adam_state(self.opt, ck.train_state)
        self.generator.set_state(ck.train_state["generator"])
        self.elapsed = float(ck.train_state["elapsed"])
        self.step = ck.step
        self.skipped_steps = int(ck.meta.get("provenance", {}).get("skipped_steps", 0))
        self.code_choice = ck.meta.get("held_out_codes")

    # ---- one step --------------------------------------------------------------------------------------
    def lr_at(self, progress: float) -> float:
        return self.cfg.lr * 0.1 ** min(max(progress, 0.0), 1.0)

    def train_step(self, progress: float) -> dict[str, float]:
        fs, g = self.frames, self.generator
        for group in self.opt.param_groups:
            group["lr"] = self.lr_at(progress) * group["lr_scale"]
        frame_ids = torch.randint(len(fs), (self.frames_per_step,), generator=g)
        terms: dict[str, torch.Tensor] = {}
        total = torch.zeros((), device=self.device)
        per_frame = self.rays_per_step // self.frames_per_step
        with self.avatar.training_step():
            for fid in frame_ids.tolist():
                if len(fs.active_index[fid]) == 0:
                    continue
                pick = self.avatar.draw_training_pixels(fs.active_index[fid], fs.pixel_count, per_frame, g).long()
                target = fs.target(fid, pick)
                known = torch.isfinite(target).all(-1)
                if not bool(known.all()):  # a colour that is no number teaches nothing, and makes the loss NaN
                    pick, target = pick[known], target[known]
                    if len(pick) == 0:
                        continue
                rays = fs.rays(fid, pick).to(self.device)
                target = target.to(self.device)
                parts = self.avatar.loss_terms(TrainingBatch(fid, rays, target, fs.geometry[fid], progress, g))
                for k, v in parts.items():
                    terms[k] = terms.get(k, 0.0) + v.detach() / len(frame_ids)
                    total = total + v / len(frame_ids)
        self.step += 1
        numbers, stepped = optimiser_step(self.opt, self.avatar, total, terms, self.cfg.grad_clip)
        self.skipped_steps += not stepped
        return numbers

    # ---- validation ------------------------------------------------------------------------------------
    @torch.no_grad()
    def validation_psnr(self, gl: GLContext) -> float:
        v = self.validation
        r = Rasterizer(gl)
        img = render_image(self.avatar, v.camera, v.controls, RenderOptions(room=v.room, time_s=v.time_s),
                           rasterizer=r)["rgb"]
        r.release()
        return psnr(img, v.image)

    def choose_code_time(self, gl: GLContext, on_frame: Callable[[int, int], None] | None = None) -> dict | None:
        """choose_code_time on this run's avatar and validation frames (after its budget), kept for its meta."""
        if self.val_split is None:
            return None
        self.code_choice = choose_code_time(self.avatar, self.val_split, gl, on_frame)
        return self.code_choice

    # ---- the loop --------------------------------------------------------------------------------------
    def run(self, gl: GLContext, on_progress: Callable[[dict], None] | None = None) -> dict:
        cfg = self.cfg
        budget_s = cfg.minutes * 60 if cfg.minutes else math.inf
        budget_steps = cfg.steps if cfg.steps else math.inf
        if budget_s == math.inf and budget_steps == math.inf:
            budget_steps = DEFAULT_STEPS
        log = Path(cfg.out) / "progress.jsonl"
        Path(cfg.out).mkdir(parents=True, exist_ok=True)
        trim_progress(log, self.step)
        last_ck = last_record = time.perf_counter()
        start_elapsed, t0 = self.elapsed, time.perf_counter()
        record: dict = {}
        while self.step < budget_steps and self.elapsed < budget_s and not self.stop_requested:
            progress = max(self.step / budget_steps if budget_steps != math.inf else 0.0,
                           self.elapsed / budget_s if budget_s != math.inf else 0.0)
            terms = self.train_step(progress)
            self.elapsed = start_elapsed + time.perf_counter() - t0
            finished = (self.step >= budget_steps or self.elapsed >= budget_s or self.stop_requested)
            if (self.step % 50 == 0 or self.step == 1 or finished  # the last step is always logged
                    or time.perf_counter() - last_record >= PROGRESS_SECONDS):
                last_record = time.perf_counter()
                rate = self.step / max(self.elapsed, 1e-9)
                eta = max(0.0, min((budget_steps - self.step) / max(rate, 1e-9) if budget_steps != math.inf
                                   else math.inf, budget_s - self.elapsed))
                record = {"step": self.step, **finite_terms(terms),
                          "elapsed_s": round(self.elapsed, 1), "eta_s": round(eta, 1)}
                if self.skipped_steps:
                    record["skipped_steps"] = self.skipped_steps
                if self.validation is not None and (self.step % 250 == 0 or finished):
                    record["val_psnr"] = round(self.validation_psnr(gl), 2)
                log_progress(log, record, on_progress)
            if time.perf_counter() - last_ck > cfg.checkpoint_seconds:
                self.save()
                last_ck = time.perf_counter()
        self.save()
        return record


@torch.no_grad()
def choose_code_time(avatar: Avatar, val_split: CaptureSplit, gl: GLContext,
                     on_frame: Callable[[int, int], None] | None = None) -> dict | None:
    """Whether the video's own frames that no one trained on (held-out frames) take the codes of the training
    frames nearest in controls and time (components/codes.py), or in controls alone: each validation frame filmed
    late enough is rendered both ways from the codes of the training frames filmed FORECAST_GAP_S or more before it
    (as a held-out frame after them has them), and the way with the higher mean PSNR is kept (controls alone where
    they tie or no frame says). None where the avatar's training frames have no times. on_frame(done, total) after
    each render."""
    keys = avatar.code_keys
    if keys.times is None:
        return None
    frames = [i for i, f in enumerate(val_split.frames) if f.time_s is not None and keys.forecastable(f.time_s)]
    scores: dict[float | None, list[float]] = {None: [], TIME_SCALE_S: []}
    r, background = Rasterizer(gl), avatar.background_colour()
    for i in frames:
        v = validation_frame(val_split, background, i)
        for scale, got in scores.items():
            with keys.forecasting(scale):
                img = render_image(avatar, v.camera, v.controls, RenderOptions(room=v.room, time_s=v.time_s),
                                   rasterizer=r)["rgb"]
            got.append(psnr(img, v.image))
            if on_frame is not None:
                on_frame(sum(map(len, scores.values())), 2 * len(frames))
    r.release()
    by_time = bool(frames) and float(np.mean(scores[TIME_SCALE_S])) > float(np.mean(scores[None]))
    keys.choose_time(TIME_SCALE_S if by_time else None)
    return {"by_time": by_time, "frames": len(frames),
            **({"psnr_controls": round(float(np.mean(scores[None])), 2),
                "psnr_controls_and_time": round(float(np.mean(scores[TIME_SCALE_S])), 2)} if frames else {})}


def optimiser_step(opt: torch.optim.Optimizer, model: torch.nn.Module, total: torch.Tensor, terms: dict,
                   grad_clip: float) -> tuple[dict[str, float], bool]:
    """Backward, the gradient clipped to grad_clip (second derivatives, density-gradient normals, can spike; a
    bounded step keeps the field alive), Adam's step; the step's loss terms as numbers, and whether it stepped.

    A step whose loss or gradient norm is not finite (a NaN term, a NaN target) is skipped: its gradient dropped,
    the weights and Adam's moments left as they were. Taken, clip_grad_norm_ would scale every gradient by NaN and
    Adam write NaN into every weight and moment. Under torch.distributed every process skips if any must (their
    weights stay the same). The finite path's arithmetic is the plain backward, clip and step."""
    opt.zero_grad(set_to_none=True)
    total.backward()
    norm = torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
    finite = (torch.isfinite(total.detach()) & torch.isfinite(norm)).to(torch.int32)
    if dist.is_available() and dist.is_initialized():
        dist.all_reduce(finite, op=dist.ReduceOp.MIN)
    stepped = bool(finite)
    if stepped:
        opt.step()
    else:
        opt.zero_grad(set_to_none=True)
    return {k: float(v) for k, v in terms.items()} | {"loss": float(total.detach())}, stepped


def finite_terms(terms: dict[str, float]) -> dict[str, float]:
    """A step's loss terms for the progress log, rounded; a skipped step's NaN or infinite ones left out (JSON has
    no NaN)."""
    return {k: round(v, 6) for k, v in terms.items() if math.isfinite(v)}


def log_progress(log: Path, record: dict, on_progress: Callable[[dict], None] | None) -> None:
    """One record appended to progress.jsonl, and shown."""
    with open(log, "a") as f:
        f.write(json.dumps(record) + "\n")
    if on_progress:
        on_progress(record)
