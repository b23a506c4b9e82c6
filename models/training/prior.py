"""Training the universal prior (Cao et al. 2022, Section 3.3) on a corpus of identities, in one process or several
through torch.distributed (DistributedDataParallel; `torchrun --nproc-per-node N avatar-studio prior-train ...`:
CPU processes talk over gloo, GPUs over NCCL).

Every process holds the whole corpus and draws the same samples (the same seeded generator): a step's global
list of (identity, frame) samples, each with its pixels, is dealt round the processes (sample k to rank
k mod N); each process's loss is the mean over its share and DDP averages the gradients, so N processes take the
step one process takes on the whole list (the test holds them equal). Each sample's random draws (the expression
code's noise) come from its own generator, seeded by the step and the sample, wherever it runs. Rank 0 writes the
checkpoints (safetensors + JSON, atomic, resumable, as every avatar's)."""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist
from torch import nn

from models.avatars.base import TrainingBatch
from models.avatars.checkpoint import load_checkpoint, read_meta, save_checkpoint
from models.avatars.components.plate import Plate
from models.avatars.effects import parse_effects
from models.avatars.prior.avatar import PriorAvatar, PriorConfig
from models.avatars.prior.maps import (
    average_texture,
    beyond_head,
    eye_heights,
    eye_vertices,
    hair_colour,
    hair_pixels,
    hair_reach_m,
    texture_map,
    texture_tensor,
)
from models.capture.dataset import CaptureSplit, load_split
from models.capture.frames import background_plate, frame_camera, load_mask, load_rgb
from models.device import DeviceError, device_of
from models.head.sources import head_kind, load_head
from models.ranges import OptionError
from models.training.configs import PriorTrainConfig
from models.training.data import FrameSet, build_frames
from models.training.trainer import (
    _adam_state_tensors,
    _load_adam_state,
    finite_terms,
    log_progress,
    model_options,
    optimiser_step,
    trim_progress,
)
from render.camera import project
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

NEUTRAL_FRAMES = 8
"""The frames of least expression whose colours make an identity's neutral texture."""


@dataclass
class Identity:
    """One person of the corpus: their frames and neutral conditioning maps (1,3,S,S each)."""

    name: str
    frames: FrameSet
    texture: torch.Tensor
    geometry: torch.Tensor


@dataclass
class NeutralViews:
    """What a capture's least expressive frames saw of the head: each frame's colours (S,S,3) and weights (S,S)
    unprojected onto the chart (maps.texture_map); the hair's colour (3,) from the person's pixels beyond the mesh
    above the eyes (maps.hair_colour; None where the frames have no masks or show too little beyond it), and how
    far below the eyes the hair hangs (metres, the frames' median of maps.hair_reach_m; 0 without a colour)."""

    colours: list[np.ndarray]
    weights: list[np.ndarray]
    hair: np.ndarray | None
    hair_reach_m: float = 0.0


def neutral_views(split: CaptureSplit, avatar: PriorAvatar, gl: GLContext, frames: int = NEUTRAL_FRAMES
                  ) -> NeutralViews:
    """The split's `frames` least expressive frames' views of the head (NeutralViews)."""
    amount = [float(np.abs(f.controls.expression).sum() + np.abs(f.controls.rotation("jaw")).sum())
              for f in split.frames]
    raster = Rasterizer(gl)
    colours, weights, beside, head_pixels = [], [], [], 0
    bg = avatar.background_colour()
    eyes = eye_vertices(avatar.head_model)
    for k in np.argsort(amount)[:frames]:
        f = split.frames[int(k)]
        geo = avatar.geometry(f.controls)
        cam = frame_camera(split, f)
        posed = geo.posed.cpu().numpy()
        r = raster.rasterize(posed, avatar.head_model.triangles, cam)
        image = load_rgb(f.image_path, bg)
        c, w = texture_map(avatar.sampler, avatar.triangles.cpu(), geo.posed.cpu(), cam, image, r)
        colours.append(c)
        weights.append(w)
        person = load_mask(f.extra["mask_path"]) > 0.5 if "mask_path" in f.extra else None
        if person is not None and person.shape == image.shape[:2]:
            _, y, depth = project(cam, posed[eyes])
            eye_row, px_per_m = float(y.mean()), cam.intrinsics[1] / float(depth.mean())
            beside.append((image, beyond_head(person, r.hit), eye_row, px_per_m))
            head_pixels += int(r.hit[: max(int(eye_row), 0)].sum())
    raster.release()
    hair = hair_colour([hair_pixels(image, beyond, row) for image, beyond, row, _ in beside], head_pixels)
    reach = 0.0 if hair is None else float(np.median([hair_reach_m(image, beyond, hair, row, px_per_m)
                                                      for image, beyond, row, px_per_m in beside]))
    return NeutralViews(colours, weights, hair, reach)


def neutral_texture(split: CaptureSplit, avatar: PriorAvatar, gl: GLContext, frames: int = NEUTRAL_FRAMES
                    ) -> torch.Tensor:
    """(1,3,S,S) the colours of the split's `frames` least expressive frames, unprojected onto the chart and
    averaged (the seed's view-averaged neutral texture; the back of the head none sees takes the hair's colour,
    or the crown's, down to where long hair hangs; the rest of what none sees is filled from around:
    average_texture)."""
    views = neutral_views(split, avatar, gl, frames)
    texture, _ = average_texture(views.colours, views.weights, heights=eye_heights(avatar.head_model, avatar.sampler),
                                 hair=views.hair, hair_reach_m=views.hair_reach_m)
    return texture_tensor(texture)[None]


def load_identity(folder: Path, avatar: PriorAvatar, gl: GLContext) -> Identity:
    """One person's training frames and neutral maps. A tracked video's frames composite over its own room (its
    background plate, kept in the frames), as `train` composites them; the prior keeps no one's room."""
    split = load_split(folder, "train")
    plate = background_plate(split)
    if plate is not None:
        avatar.plate.note(*plate)
    frames = build_frames(split, avatar, gl)
    avatar.plate = Plate()
    shape = split.frames[0].controls.shape
    ident = Identity(folder.name, frames, neutral_texture(split, avatar, gl),
                     avatar.neutral_geometry_of(shape).detach())
    for geo in frames.geometry:
        geo.identity = (ident.texture, ident.geometry)
    return ident


def corpus_folders(corpus: Path, people: Sequence[Path] = ()) -> list[Path]:
    """The captures of a corpus folder (one folder per identity, `corpus`) and the further people given one
    capture each (a tracked video's, `track`); all of one head model (the prior's chart is that model's)."""
    found = sorted(p for p in Path(corpus).iterdir() if (p / "transforms_train.json").is_file()) \
        if Path(corpus).is_dir() else []
    if not found:
        raise FileNotFoundError(f"{corpus}: no captures (folders with transforms_train.json) in it")
    for p in people:
        if not (Path(p) / "transforms_train.json").is_file():
            raise FileNotFoundError(f"{p}: not a capture (no transforms_train.json in it; `track VIDEO` makes one)")
    folders = found + [Path(p) for p in people]
    names = [f.name for f in folders]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"{', '.join(twice)}: more than one person of that name in the corpus (the prior names "
                         "its people by their folders)")
    kinds = {f: capture_head_kind(f) for f in folders}
    first = kinds[folders[0]]
    other = next((f for f in folders if kinds[f] != first), None)
    if other is not None:
        raise ValueError(f"{other}: its head model is {kinds[other]}, the corpus's ({folders[0]}) {first}; a prior "
                         f"is trained on people of one head model (track the video with --head {first})")
    return folders


def capture_head_kind(capture: Path) -> str:
    """The kind of a capture's head model, as its transforms_train.json names it."""
    with open(Path(capture) / "transforms_train.json") as f:
        return head_kind(json.load(f).get("head_model"))


class PriorLoss(nn.Module):
    """The prior's loss over a list of samples, as one module's forward (what DDP wraps)."""

    def __init__(self, avatar: PriorAvatar):
        super().__init__()
        self.avatar = avatar

    def forward(self, batches: list[TrainingBatch]) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        total = torch.zeros((), device=self.avatar.background.device)
        terms: dict[str, torch.Tensor] = {}
        for b in batches:
            for k, v in self.avatar.loss_terms(b).items():
                terms[k] = terms.get(k, 0.0) + v.detach() / len(batches)
                total = total + v / len(batches)
        return total, terms


class PriorTrainer:
    def __init__(self, cfg: PriorTrainConfig, avatar: PriorAvatar, identities: list[Identity], rank: int = 0,
                 world: int = 1):
        if cfg.frames_per_step % world:
            raise ValueError(f"--frames-per-step {cfg.frames_per_step}: not a multiple of the {world} processes")
        self.cfg, self.avatar, self.identities, self.rank, self.world = cfg, avatar, identities, rank, world
        device_of(cfg.device)  # (a clear error where there is no GPU)
        self.device = process_device(cfg.device)
        avatar.to(self.device)
        for ident in identities:
            ident.frames.geometry = [g.to(self.device) for g in ident.frames.geometry]
        self.loss = PriorLoss(avatar)
        self.module = self.loss if world == 1 else nn.parallel.DistributedDataParallel(
            self.loss, device_ids=None if self.device.type == "cpu" else [self.device], find_unused_parameters=True)
        self.opt = torch.optim.Adam(avatar.parameters(), lr=cfg.lr)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.step = 0
        self.skipped_steps = 0
        """Steps whose loss or gradient was not finite, left out (optimiser_step)."""
        self.elapsed = 0.0

    def samples(self) -> list[TrainingBatch]:
        """The step's samples this process takes (every process draws them all, in the same order)."""
        g, out = self.generator, []
        for k in range(self.cfg.frames_per_step):
            ident = self.identities[int(torch.randint(len(self.identities), (1,), generator=g))]
            fs = ident.frames
            fid = int(torch.randint(len(fs), (1,), generator=g))
            idx = fs.active_index[fid]
            pick = (idx[torch.randint(len(idx), (self.cfg.rays_per_frame,), generator=g)] if len(idx) else idx).long()
            if k % self.world != self.rank or len(pick) == 0:
                continue
            rays = fs.rays(fid, pick).to(self.device)
            own = torch.Generator().manual_seed(self.cfg.seed * 1_000_003 + self.step * 4096 + k)
            out.append(TrainingBatch(fid, rays, fs.target(fid, pick).to(self.device),
                                     fs.geometry[fid], 0.0, own))
        return out

    def train_step(self, progress: float) -> dict[str, float]:
        for group in self.opt.param_groups:
            group["lr"] = self.cfg.lr * 0.1 ** min(max(progress, 0.0), 1.0)
        total, terms = self.module(self.samples())
        self.step += 1
        numbers, stepped = optimiser_step(self.opt, self.avatar, total, terms, self.cfg.grad_clip)
        self.skipped_steps += not stepped
        return numbers

    # ---- state -----------------------------------------------------------------------------------------
    def meta(self) -> dict:
        split = self.identities[0].frames.split
        return {**self.avatar.meta(), "head_model": split.head_model, "frames": len(self.avatar.latent.weight),
                "image_px": [split.width, split.height], "background": self.avatar.background.tolist(),
                "corpus": {"folder": str(self.cfg.corpus), "people": [str(p) for p in self.cfg.people],
                           "identities": [i.name for i in self.identities]},
                "provenance": {"steps": self.step, "skipped_steps": self.skipped_steps,
                               "seconds": round(self.elapsed, 1), "processes": self.world,
                               "config": {k: str(v) for k, v in asdict(self.cfg).items()}}}

    def save(self) -> None:
        if self.rank != 0:
            return
        state = _adam_state_tensors(self.opt)
        state["generator"] = self.generator.get_state()
        state["elapsed"] = torch.tensor(self.elapsed, dtype=torch.float64)
        save_checkpoint(self.cfg.out, self.meta(), self.avatar.state_dict(), self.step, state)

    def resume(self) -> None:
        ck = load_checkpoint(self.cfg.out, with_train_state=True)
        self.avatar.load_state_dict(ck.weights)
        _load_adam_state(self.opt, ck.train_state)
        self.generator.set_state(ck.train_state["generator"])
        self.elapsed = float(ck.train_state["elapsed"])
        self.step = ck.step
        self.skipped_steps = int(ck.meta.get("provenance", {}).get("skipped_steps", 0))

    def run(self, on_progress: Callable[[dict], None] | None = None) -> dict:
        cfg = self.cfg
        budget_s = cfg.minutes * 60 if cfg.minutes else math.inf
        budget_steps = cfg.steps or (2000 if budget_s == math.inf else math.inf)
        log = Path(cfg.out) / "progress.jsonl"
        if self.rank == 0:
            Path(cfg.out).mkdir(parents=True, exist_ok=True)
            trim_progress(log, self.step)
        last_ck, start, t0 = time.perf_counter(), self.elapsed, time.perf_counter()
        record: dict = {}
        while self.step < budget_steps and self.elapsed < budget_s:
            progress = max(self.step / budget_steps if budget_steps != math.inf else 0.0,
                           self.elapsed / budget_s if budget_s != math.inf else 0.0)
            terms = self.train_step(progress)
            self.elapsed = start + time.perf_counter() - t0
            if self.world > 1:  # every process stops on the same step: rank 0's clock decides
                clock = torch.tensor([self.elapsed], dtype=torch.float64)
                dist.broadcast(clock, 0)
                self.elapsed = float(clock)
            finished = self.step >= budget_steps or self.elapsed >= budget_s
            if self.rank == 0 and (self.step % 50 == 0 or self.step == 1 or finished):
                record = {"step": self.step, **finite_terms(terms), "elapsed_s": round(self.elapsed, 1)}
                if self.skipped_steps:
                    record["skipped_steps"] = self.skipped_steps
                log_progress(log, record, on_progress)
            if time.perf_counter() - last_ck > cfg.checkpoint_seconds:
                self.save()
                last_ck = time.perf_counter()
        self.save()
        return record


BACKENDS = {"cpu": "gloo", "cuda": "cpu:gloo,cuda:nccl"}
"""torch.distributed's backend for each --device. On GPUs the gradients go over NCCL, and the few CPU tensors
(rank 0's clock, which every process stops on) over gloo: NCCL takes CUDA tensors only."""


def distributed_from_env(device: str = "cpu") -> tuple[int, int]:
    """(rank, world size) under torchrun (RANK, WORLD_SIZE in the environment; the process group started with
    BACKENDS[device], each GPU process on its own GPU first, process_device), else (0, 1)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1
    if not dist.is_initialized():
        if device == "cuda":  # NCCL refuses two ranks on one GPU, and takes the current device as the rank's
            torch.cuda.set_device(process_device(device))
        dist.init_process_group(BACKENDS[device])
    return dist.get_rank(), dist.get_world_size()


def process_device(device: str, environ: Mapping[str, str] = os.environ,
                   gpus: Callable[[], int] = torch.cuda.device_count) -> torch.device:
    """This process's device: the CPU, or under torchrun the GPU of its LOCAL_RANK (one GPU a process, as NCCL
    needs; torchrun numbers a node's processes 0..N-1); a clear error where the node has fewer GPUs.

    >>> process_device("cuda", {"LOCAL_RANK": "1", "WORLD_SIZE": "2"}, lambda: 2)
    device(type='cuda', index=1)
    >>> process_device("cuda", {}, lambda: 1)  # one process: the current GPU
    device(type='cuda', index=0)
    >>> process_device("cpu", {"LOCAL_RANK": "1", "WORLD_SIZE": "2"}, lambda: 0)
    device(type='cpu')
    """
    if device != "cuda":
        return torch.device(device)
    local = int(environ.get("LOCAL_RANK", "0"))
    if local >= gpus():
        raise DeviceError(f"--device cuda: process {local} of this node needs GPU {local}, and torch sees "
                          f"{gpus()}; start at most that many processes (torchrun --nproc-per-node)")
    return torch.device("cuda", local)


def prepare_prior(cfg: PriorTrainConfig, gl: GLContext, rank: int = 0, world: int = 1,
                  on_identity: Callable[[int, int], None] | None = None) -> PriorTrainer:
    """The prior and its corpus read from disk (every process reads it all); on_identity(done, total) after each
    identity's frames and maps are ready (a corpus of 24 takes minutes)."""
    folders = corpus_folders(cfg.corpus, cfg.people)
    first = load_split(folders[0], "train")
    head = load_head(first.head_model)
    torch.manual_seed(cfg.seed)
    if cfg.resume:  # the settings the prior was begun with
        if cfg.model_options:
            raise OptionError(f"{cfg.out}: --model-options with --resume; the prior keeps the settings it was begun "
                              "with (its avatar.json)")
        pcfg = PriorConfig(**read_meta(cfg.out)[PriorAvatar.config_key])
    else:
        pcfg = model_options(PriorAvatar, cfg.model_options,
                             PriorConfig(grid=cfg.grid, voxels=cfg.voxels, width=cfg.width, kl=cfg.kl))
    avatar = PriorAvatar.for_capture(head, 1, first.background, parse_effects(cfg.effects), first.lighting, pcfg)
    identities = []
    for f in folders:
        identities.append(load_identity(f, avatar, gl))
        if on_identity is not None:
            on_identity(len(identities), len(folders))
    trainer = PriorTrainer(cfg, avatar, identities, rank, world)
    if cfg.resume:
        trainer.resume()
    return trainer
