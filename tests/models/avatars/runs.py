"""Tiny training runs shared by the models' tests."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from models.avatars.registry import load_avatar
from models.avatars.rendering import render_image
from models.capture.frames import frame_camera
from models.training.trainer import prepare_training
from render.gl.raster import Rasterizer


def photometric_before_and_after(trainer, steps: int) -> tuple[float, float]:
    """Run `steps` steps; the mean photometric error of the first three and of the last three."""
    first = float(np.mean([trainer.train_step(0.0)["photometric"] for _ in range(3)]))
    for k in range(3, steps - 3):
        trainer.train_step(k / steps)
    last = float(np.mean([trainer.train_step(1.0)["photometric"] for _ in range(3)]))
    return first, last


def saved_and_reloaded(trainer):
    """Save the run and load it back as an avatar folder: (avatar, meta), its weights checked equal."""
    trainer.save()
    avatar, meta = load_avatar(trainer.cfg.out)
    for k, v in trainer.avatar.state_dict().items():
        assert torch.equal(v, avatar.state_dict()[k]), k
    return avatar, meta


def with_frame_times(capture: Path, out: Path) -> Path:
    """A copy of a capture made to read as a tracked video's (a `source` video: a video's model settings, per-frame
    codes keyed by controls and time, the codes' choice after training) whose frames have times in the video
    (`time_s`, as `track` writes): the training frames 0.1 s apart from 0, the validation and test frames 0.1 s
    apart from 0.35 s after the last, so that every training frame was filmed long enough before them for the
    codes' choice (FORECAST_GAP_S)."""
    shutil.copytree(capture, out)
    after = 0.1 * len(json.loads((out / "transforms_train.json").read_text())["frames"]) + 0.25
    for split, start in (("train", 0.0), ("val", after), ("test", after)):
        path = out / f"transforms_{split}.json"
        meta = json.loads(path.read_text())
        meta["source"] = {"video": "synthetic.mp4"}
        for i, frame in enumerate(meta["frames"]):
            frame["time_s"] = round(start + 0.1 * i, 3)
        path.write_text(json.dumps(meta))
    return out


def gpu_run_matches_cpu(cfg, gl, progress: float, buffers: tuple[str, ...] = ("rgb",)) -> None:
    """The same 4 steps (same seed, same rays: the generator stays on the CPU) on the GPU and the CPU give the same
    losses and weights to float tolerance, and the same validation PSNR (and codes' choice, where the capture has
    frame times) from the trainer's own renders; the GPU's saved avatar, loaded on the GPU, renders the first
    training frame as the CPU's does (each buffer within 0.01)."""
    cpu, gpu = prepare_training(cfg, gl), prepare_training(replace(cfg, out=cfg.out.parent / "gpu", device="cuda"), gl)
    for _ in range(4):
        a, b = cpu.train_step(progress), gpu.train_step(progress)
        assert b["loss"] == pytest.approx(a["loss"], rel=1e-3)
    # Adam divides each gradient by its own running scale, so a weight whose gradient is at rounding level (where
    # the two devices' sums differ in sign) moves by up to lr in either direction a step: such weights may part by
    # 2 lr per step (0.04 here), and only they may: a few in a hundred. Measured on an H100: 12 of CoDyNeRF's 1024
    # first-layer weights beyond 1e-3 (the largest 1.4e-3), 1 of the 32 biases of its normals network's last layer.
    bound, apart, count = 2 * cfg.lr * 4, 0, 0
    for k, v in cpu.avatar.state_dict().items():
        g, c = gpu.avatar.state_dict()[k].cpu().float(), v.float()
        assert (g - c).abs().max() <= bound, k
        apart, count = apart + int(((g - c).abs() > 1e-3 + 1e-3 * c.abs()).sum()), count + c.numel()
    assert apart <= 0.02 * count, (apart, count)
    # the trainer's own renders on the GPU (validation, the codes' choice) with what its first pass made on the CPU
    assert gpu.validation_psnr(gl) == pytest.approx(cpu.validation_psnr(gl), abs=0.05)
    on_cpu, on_gpu = cpu.choose_code_time(gl), gpu.choose_code_time(gl)
    assert (on_gpu is None) == (on_cpu is None)  # None: the capture has no frame times
    for key in ("psnr_controls", "psnr_controls_and_time") if on_cpu else ():
        assert on_gpu[key] == pytest.approx(on_cpu[key], abs=0.05), key
    gpu.save()
    avatar, _ = load_avatar(gpu.cfg.out, "cuda")
    f = cpu.split.frames[0]
    cam, r = frame_camera(cpu.split, f), Rasterizer(gl)
    on_gpu = render_image(avatar, cam, f.controls, rasterizer=r)
    on_cpu = render_image(cpu.avatar, cam, f.controls, rasterizer=r)
    for name in buffers:
        assert np.isfinite(on_gpu[name]).all() and np.abs(on_gpu[name] - on_cpu[name]).max() < 0.01, name
