"""Per-frame head pose corrections of a tracked video, on CoDyNeRF and the primitives alike: the rays they give
against an independent rotation, zero corrections change nothing, the photometric loss reaches them (finite
gradients), they learn at their own rate, and they are saved with the avatar. The primitives' expression
corrections: the mesh posed again with the corrected weights, against the head model posing those weights."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from models.avatars.checkpoint import save_checkpoint
from models.avatars.components.poses import EXPRESSION_LR_RATIO, POSE_LR_SCALE
from models.avatars.registry import load_avatar
from models.head.controls import Controls
from render.gl.raster import Rasterizer
from render.rays import Rays
from tests.conftest import BUILTIN_AVATAR as DEMO  # a head with a jaw joint
from tests.conftest import CODYNERF_DEMO

AVATARS = pytest.mark.parametrize("folder", [CODYNERF_DEMO, DEMO], ids=["codynerf", "primitives"])


def rays_at_head(avatar, gl, n: int = 64, seed: int = 0) -> tuple[Rays, object]:
    """n rays from 0.6 m in front of the neutral head towards points about its centre (no mesh distances)."""
    r = Rasterizer(gl)
    geo = avatar.frame_geometry(Controls(), r)  # the demo's shadow factor reads the light's depth map
    r.release()
    centre = avatar.pose_centre(geo)
    g = torch.Generator().manual_seed(seed)
    target = centre + 0.04 * torch.randn(n, 3, generator=g)
    origin = centre + torch.tensor([0.0, 0.0, 0.6])
    d = target - origin
    return Rays(origin.expand(n, 3), d / d.norm(dim=-1, keepdim=True), torch.full((n,), float("inf"))), geo


@pytest.mark.gl
@AVATARS
def test_corrected_rays_against_an_independent_rotation(gl, folder):
    avatar, _ = load_avatar(folder)
    avatar.fit_to_tracked_video(True)
    rays, geo = rays_at_head(avatar, gl, 8)
    n = avatar.pose_corrections.shape[0]
    with torch.no_grad():
        avatar.pose_corrections[0] = torch.tensor([0.05, -0.03, 0.02, 0.004, -0.002, 0.003])
    effective = (avatar.pose_corrections[0] * (1 - 1 / n)).detach().numpy()  # less the mean over n frames
    out = avatar.corrected_rays(rays, geo, 0)
    rot = Rotation.from_rotvec(effective[:3].astype(np.float64)).as_matrix()
    c = avatar.pose_centre(geo).numpy().astype(np.float64)
    for s in (0.0, 0.3, 0.7):  # points along each ray map to R^T (p - c - t) + c
        p = rays.origins.numpy() + s * rays.directions.numpy()
        want = (p - c - effective[3:]) @ rot + c
        got = out.origins.detach().numpy() + s * out.directions.detach().numpy()
        np.testing.assert_allclose(got, want, atol=1e-6)


@pytest.mark.gl
@AVATARS
def test_zero_corrections_change_nothing_and_the_loss_reaches_them(gl, folder):
    avatar, _ = load_avatar(folder)
    rays, geo = rays_at_head(avatar, gl)
    plain = avatar.render_rays(rays, geo, 0).buffers["rgb"].detach()
    avatar.fit_to_tracked_video(True)
    zero = avatar.render_rays(rays, geo, 0).buffers["rgb"].detach()
    torch.testing.assert_close(zero, plain, atol=1e-5, rtol=0)
    target = plain.flip(0)  # some other colours
    out = avatar.render_rays(rays, geo, 3, training=True)
    ((out.buffers["rgb"] - target) ** 2).mean().backward()
    corrections = [avatar.pose_corrections]
    if folder == DEMO:
        corrections.append(avatar.expression_corrections)
    for c in corrections:
        grad = c.grad
        assert torch.isfinite(grad).all() and grad[3].abs().sum() > 0
        # Every frame's correction is measured from the mean of all: the others see -1/N of frame 3's gradient.
        torch.testing.assert_close(grad[0], -grad[3] / (c.shape[0] - 1), rtol=1e-4, atol=1e-12)
    # Held-out frames and new controls (frame None) use the tracked pose as it is.
    torch.testing.assert_close(avatar.render_rays(rays, geo, None).buffers["rgb"],
                               load_avatar(folder)[0].render_rays(rays, geo, None).buffers["rgb"])


@AVATARS
def test_corrections_learn_slowly_and_are_saved(tmp_path, folder):
    avatar, meta = load_avatar(folder)
    avatar.fit_to_tracked_video(True)
    if folder == CODYNERF_DEMO:
        assert avatar.loss_weights.cauchy == 0.0  # an opaque head in front of the room
        assert not avatar.loss_weights.consistency_shapes_density  # Eq. 13 pulls the normals only
    groups = avatar.parameter_groups()
    corrections = [avatar.pose_corrections] + ([avatar.expression_corrections] if folder == DEMO else [])
    assert [g["lr_scale"] for g in groups] == [1.0, POSE_LR_SCALE, POSE_LR_SCALE * EXPRESSION_LR_RATIO][:len(groups)]
    assert [g["params"] for g in groups[1:]] == [[c] for c in corrections]
    assert sum(p.numel() for g in groups for p in g["params"]) == sum(p.numel() for p in avatar.parameters())
    with torch.no_grad():
        for c in corrections:
            c.normal_(0, 0.01)
    save_checkpoint(tmp_path / "av", json.loads(json.dumps(meta | avatar.meta())), avatar.state_dict(), 1)
    again, saved = load_avatar(tmp_path / "av")
    assert saved["pose_corrections"] is True and saved.get("expression_corrections", False) == (folder == DEMO)
    torch.testing.assert_close(again.pose_corrections, avatar.pose_corrections)
    if folder == DEMO:
        torch.testing.assert_close(again.expression_corrections, avatar.expression_corrections)


def test_expression_corrections_pose_the_mesh_again():
    """A training frame's decode reads the mesh the head model poses with the corrected weights (less the mean
    correction), and its condition carries them; other frames and new controls read the controls as given."""
    avatar, _ = load_avatar(DEMO)
    avatar.fit_to_tracked_video(True)
    E = avatar.head_model.num_expression
    jaw = np.array([0.1, 0.0, 0.0], np.float32)
    controls = Controls(expression=np.linspace(0.0, 0.4, E, dtype=np.float32), jaw=jaw)
    geo = avatar.geometry(controls)
    with torch.no_grad():
        avatar.expression_corrections[2] = torch.linspace(-0.2, 0.3, E)
    delta = (avatar.expression_corrections[2] * (1 - 1 / avatar.n_frames)).detach().numpy()
    posed, condition = avatar.frame_inputs(geo, 2)
    want = avatar.head.pose(Controls(expression=controls.expression + delta, jaw=controls.jaw))[0][0]
    torch.testing.assert_close(posed.detach(), want, atol=1e-6, rtol=0)
    torch.testing.assert_close(condition[0, :E].detach(), torch.as_tensor(controls.expression + delta))
    torch.testing.assert_close(condition[0, E:], geo.condition[0, E:])
    assert (posed - geo.posed).abs().max() > 1e-4  # the correction moved the mesh
    same, cond = avatar.frame_inputs(geo, None)
    assert same is geo.posed and cond is geo.condition


def test_each_model_has_its_default_and_train_can_say_otherwise():
    """A tracked video: CoDyNeRF corrects poses unless told not to; the primitives only when told (measured: their
    held-out frames, which take no correction, lost on d3; README "Real people")."""
    primitives = load_avatar(DEMO)[0]
    primitives.fit_to_tracked_video()
    assert primitives.pose_corrections is None and primitives.expression_corrections is None
    assert len(primitives.parameter_groups()) == 1
    codynerf = load_avatar(CODYNERF_DEMO)[0]
    codynerf.fit_to_tracked_video(False)
    assert codynerf.pose_corrections is None and codynerf.loss_weights.cauchy == 0.0
    codynerf.fit_to_tracked_video()
    assert codynerf.pose_corrections is not None
