"""The NerFACE baseline in the avatar's harness: its rigid pose, a tiny training run, its checkpoint and its
renders."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from models.avatars.components.rigid import kabsch
from models.avatars.nerface.avatar import NerfaceAvatar, NerfaceConfig
from models.avatars.rendering import render_image
from models.capture.frames import frame_camera
from models.head.controls import Controls
from models.training.trainer import TrainConfig, prepare_training
from render.gl.raster import Rasterizer
from render.rays import Rays
from tests.models.avatars.runs import photometric_before_and_after, saved_and_reloaded

pytestmark = pytest.mark.gl

SMALL = NerfaceConfig(width=64, depth=4, coarse_samples=16, fine_samples=16)
"""NerFACE's design at a size a test trains in seconds (the published sizes are the default)."""


def test_kabsch_recovers_a_rigid_motion():
    g = torch.Generator().manual_seed(0)
    src = torch.randn(50, 3, generator=g)
    c, s = math.cos(0.7), math.sin(0.7)
    rot = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # 0.7 rad about y
    t = torch.tensor([0.1, -0.2, 0.3])
    r_est, t_est = kabsch(src, src @ rot.T + t)
    torch.testing.assert_close(r_est, rot, atol=1e-5, rtol=0)
    torch.testing.assert_close(t_est, t, atol=1e-5, rtol=0)


def test_rigid_pose_is_the_root_rotation(builtin_model):
    avatar = NerfaceAvatar(builtin_model, SMALL, 1, np.ones(3))
    geo = avatar.geometry(Controls(root=np.array([0.0, 0.5, 0.0], np.float32),
                                   jaw=np.array([0.2, 0.0, 0.0], np.float32)))
    c, s = math.cos(0.5), math.sin(0.5)
    # The jaw moves a few vertices, so the best rigid fit is the root's rotation to within a degree.
    root = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    angle = torch.arccos(((geo.rotation.T @ root).trace() - 1) / 2)
    assert math.degrees(float(angle)) < 1.0
    jaw = builtin_model.num_expression + 3  # neck, then jaw, in the expression vector
    assert float(geo.expression[0, jaw]) == pytest.approx(0.2)


@pytest.fixture(scope="module")
def capture(synth_capture) -> Path:
    return synth_capture("studio", 16, 32)


def test_tiny_nerface_run(capture, gl, tmp_path):
    cfg = TrainConfig(dataset=capture, out=tmp_path / "nf", model="nerface", steps=100, rays_per_step=256,
                      checkpoint_seconds=1e9)
    t = prepare_training(cfg, gl, SMALL)
    first, last = photometric_before_and_after(t, 100)
    print("nerface photometric", first, "->", last)
    assert last < first / 2, (first, last)  # measured: 3.0x in 100 steps
    avatar, meta = saved_and_reloaded(t)
    assert isinstance(avatar, NerfaceAvatar) and meta["model"] == "nerface"
    f = t.split.frames[0]
    out = render_image(avatar, frame_camera(t.split, f), f.controls, rasterizer=Rasterizer(gl))
    assert out["rgb"].shape == (32, 32, 3) and np.isfinite(out["rgb"]).all()
    # Rays that miss the head's box see exactly the background.
    far = avatar.render_rays(Rays(torch.tensor([[0.0, 0.0, 5.0]]), torch.tensor([[0.0, 1.0, 0.0]]),
                                  torch.tensor([float("inf")])), avatar.geometry(Controls()), None)
    torch.testing.assert_close(far.buffers["rgb"][0], avatar.background)
