"""The whole-head avatar (models/avatars/whole/avatar.py): which part each ray shows, the mix between, the captured
views rendered exactly as the inside renders them, and a whole head made, saved, loaded and resumed by `train`."""

from __future__ import annotations

import itertools
import json
import math
import threading

import numpy as np
import pytest
import torch

from models.avatars.primitives.avatar import PrimitivesAvatar, PrimitivesConfig
from models.avatars.prior.avatar import PriorAvatar
from models.avatars.rendering import RenderOptions, pixel_rays_of, render_image
from models.avatars.whole.avatar import (
    FACING_FADE_DEG,
    OUTSIDE_STOP_BELOW,
    OUTSIDE_STRETCH,
    SEEN_FADE_DEG,
    SWEEP_DEG,
    VIEW_FADE_DEG,
    WholeHeadAvatar,
    beyond_cone_deg,
    sphere_points,
)
from models.head.controls import Controls
from models.head.sources import load_builtin
from render.camera import orbit_camera
from tests.models.avatars.prior.test_prior import SMALL

CONE_DEG = 20.0


@pytest.fixture(scope="module")
def whole() -> WholeHeadAvatar:
    """Two untrained parts of the built-in head (their own seeds: they render differently), the inside's views a
    cone of 20 degrees about the head's front."""
    head = load_builtin()
    torch.manual_seed(1)
    inside = PrimitivesAvatar.for_capture(head, 4, np.full(3, 0.2, np.float32), (), None,
                                          PrimitivesConfig(grid=8, voxels=2, width=16))
    torch.manual_seed(2)
    outside = PriorAvatar.for_capture(head, 1, np.full(3, 0.7, np.float32), (), None, SMALL)
    inside.views.keep("axis", torch.tensor([0.0, 0.0, 1.0]))
    inside.views.keep("cos", torch.tensor(math.cos(math.radians(CONE_DEG))))
    return WholeHeadAvatar(inside, outside).eval()


def rays_and_weights(whole: WholeHeadAvatar, yaw_deg: float, size: int = 32):
    cam = orbit_camera(yaw_deg, 0.0, 0.6, width_px=size, height_px=size)
    geo = whole.frame_geometry(Controls(), None)
    rays, _ = pixel_rays_of(whole, geo, cam, None)
    with torch.inference_mode():
        return cam, geo, rays, whole.inside_weight(rays, geo)


def test_the_captured_views_render_as_the_inside_alone(whole):
    """A camera inside the cone: every ray the inside's (weight exactly 1), the image bit for bit the inside's."""
    cam, _, _, w = rays_and_weights(whole, 15.0)
    assert torch.all(w == 1.0)
    a = render_image(whole, cam, Controls(), RenderOptions(buffers=()))
    b = render_image(whole.inside, cam, Controls(), RenderOptions(buffers=()))
    for name in ("rgb", "opacity", "depth"):
        np.testing.assert_array_equal(a[name], b[name])


def test_behind_the_head_the_outside_and_between_a_mix(whole):
    """From behind, the rays that meet the head where it faces away (over 40 degrees beyond the cone) are the
    outside's alone; from a camera 20 degrees beyond the cone, rays are both parts' buffers mixed by the weight,
    worked out here from the parts' own renders of the same rays."""
    _, geo, rays, w = rays_and_weights(whole, 180.0)
    head_rays = (rays.origins + rays.directions * 0.6 - geo.centre).norm(dim=-1) < geo.radius  # through its middle
    assert torch.all(w[head_rays] == 0.0)

    _, geo, rays, w = rays_and_weights(whole, CONE_DEG + 20.0)
    mixed = (w > 0.01) & (w < 0.99)
    assert mixed.sum() > 20 and (w == 0.0).any()
    with torch.inference_mode():
        out = whole.render_rays(rays, geo, None)
        a = whole.inside.render_rays(rays, geo.inside, None).buffers
        b = whole.outside.render_rays(rays, geo.outside, None).buffers
    ww = w[:, None]  # the march's waves sum a subset of rays in another order: within 1e-3, where w moves it by 0.01-1
    torch.testing.assert_close(out.buffers["rgb"], ww * a["rgb"] + (1 - ww) * b["rgb"], atol=1e-3, rtol=0)
    torch.testing.assert_close(out.buffers["opacity"], w * a["opacity"] + (1 - w) * b["opacity"], atol=1e-3, rtol=0)
    assert torch.isfinite(out.buffers["rgb"]).all()


def sides_deg(whole: WholeHeadAvatar, geo, rays) -> torch.Tensor:
    """(R,) degrees beyond the cone that each ray's point on the head's sphere faces (the head is at rest: its
    rotation is the identity, so the head's frame is the world's)."""
    facing = sphere_points(rays.origins, rays.directions, geo.centre, geo.radius) - geo.centre
    facing = facing / facing.norm(dim=-1, keepdim=True)
    return beyond_cone_deg(facing, whole.views.axis, float(whole.views.cos))


def test_beyond_the_cone_the_boundary_sweeps_across_the_head(whole):
    """By hand: a camera 10 degrees beyond the cone is halfway through VIEW_FADE_DEG, so the inside keeps half its
    margin (60 of SWEEP_DEG's 120): rays meeting the head where it faces up to 60 degrees beyond the cone are all
    inside, 70 (halfway through FACING_FADE_DEG) half, from 80 on all outside. From 20 degrees beyond no margin is
    left, and the camera is a third of the way through SEEN_FADE_DEG (15 to 30): every ray's share is at most
    1 - (1/3)^2 (3 - 2/3) = 20/27; from 30 degrees beyond the inside has none. Until the camera's fall begins, as
    the camera turns away the inside's share of the rays falls, and only the rays near the boundary render
    twice."""
    assert VIEW_FADE_DEG == (0.0, 20.0) and FACING_FADE_DEG == (0.0, 20.0) and SWEEP_DEG == 120.0
    assert SEEN_FADE_DEG == (15.0, 30.0)
    _, geo, rays, w = rays_and_weights(whole, CONE_DEG + 10.0, size=64)
    towards = rays.origins[0] - geo.inside.translation
    assert float(beyond_cone_deg((towards / towards.norm())[None] @ geo.inside.rotation, whole.views.axis,
                                 float(whole.views.cos))) == pytest.approx(10.0, abs=0.5)
    side = sides_deg(whole, geo, rays)
    assert torch.all(w[side <= 59.0] == 1.0) and torch.all(w[side >= 81.0] == 0.0)
    near = (side - 70.0).abs() < 1.0
    assert near.sum() > 0 and torch.allclose(w[near], torch.full_like(w[near], 0.5), atol=0.1)

    _, geo, rays, w = rays_and_weights(whole, CONE_DEG + 20.0, size=64)
    side = sides_deg(whole, geo, rays)
    assert torch.allclose(w[side <= 0.0], torch.tensor(20 / 27), atol=0.01) and torch.all(w[side >= 20.0] == 0.0)
    assert torch.all(rays_and_weights(whole, CONE_DEG + 30.0, size=64)[3] == 0.0)

    inside_share, twice = [], []
    for beyond in (2.0, 8.0, 12.0, 14.0):
        w = rays_and_weights(whole, CONE_DEG + beyond, size=64)[3]
        inside_share.append(float((w > 0.0).float().mean()))
        twice.append(float(((w > 0.0) & (w < 1.0)).float().mean()))
    assert inside_share == sorted(inside_share, reverse=True) and inside_share[0] > 0.9
    assert max(twice) < 0.35


def test_well_beyond_the_cone_the_outside_alone(whole):
    """A camera 30 degrees or more beyond the cone: every ray the outside's (the inside's volume, seen from so far
    round, is its front smeared through it), the image bit for bit the outside's."""
    cam, _, _, w = rays_and_weights(whole, CONE_DEG + 40.0)
    assert torch.all(w == 0.0)
    a = render_image(whole, cam, Controls(), RenderOptions(buffers=()))
    b = render_image(whole.outside, cam, Controls(), RenderOptions(buffers=()))
    for name in ("rgb", "opacity", "depth"):
        np.testing.assert_array_equal(a[name], b[name])


def test_an_inside_that_saw_the_head_all_round_is_everywhere(whole):
    """No cone (a capture from all round): the inside renders every ray."""
    cone = whole.inside.views.axis, whole.inside.views.cos
    whole.inside.views.keep("axis", None)
    try:
        assert torch.all(rays_and_weights(whole, 180.0)[3] == 1.0)
    finally:
        whole.inside.views.keep("axis", cone[0])


def test_far_and_extreme_rays_stay_finite(whole):
    """Rays that graze the head's sphere, pass far from it, or start inside it: finite weights in [0, 1]."""
    geo = whole.frame_geometry(Controls(), None)
    from render.rays import Rays

    c = geo.centre
    origins = torch.stack([c + torch.tensor([0.0, 0.0, 5.0]), c + torch.tensor([geo.radius, 0.0, 1.0]),
                           c + torch.tensor([100.0, 0.0, 0.0]), c.clone()])
    directions = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    rays = Rays(origins, directions, torch.full((4,), float("inf")))
    w = whole.inside_weight(rays, geo)
    assert torch.isfinite(w).all() and (w >= 0).all() and (w <= 1).all()


def test_train_makes_a_whole_head_and_resumes_its_parts(tmp_path, one_second_scan, capsys):
    """`train --model whole` on a tracked video: the inside from scratch, then the prior personalised, each in
    parts/, put together as one avatar whose captured views are the inside's; the studio's progress as one run;
    stopped before it was put together, `--resume` finishes the outside with the prior it began with."""
    from app.cli import main
    from models.avatars.checkpoint import save_checkpoint
    from models.avatars.registry import load_avatar
    from models.capture.dataset import load_split
    from models.capture.frames import frame_camera
    from models.training.configs import PERSONALIZE_LR
    scan, prior, out = one_second_scan, tmp_path / "prior", tmp_path / "whole"
    torch.manual_seed(0)
    small = PriorAvatar.for_capture(load_builtin(), 1, np.full(3, 0.5, np.float32), (), None, SMALL)
    save_checkpoint(prior, {**small.meta(), "head_model": "builtin", "frames": 1, "background": [0.5] * 3},
                    small.state_dict(), 1)
    capsys.readouterr()
    assert main(["train", str(scan), "--model", "whole", "--prior", str(prior), "--out", str(out), "--steps", "4",
                 "--lr", "0.01"]) == 0
    said = capsys.readouterr().out
    assert "as a whole head" in said and "a whole head, 4 steps from scratch and 1 personalising" in said
    assert said.count("frames of the video no one trained on take the codes") == 1  # the inside's: the whole's codes
    avatar, meta = load_avatar(out)
    assert isinstance(avatar, WholeHeadAvatar) and meta["model"] == "whole" and meta["provenance"]["steps"] == 5
    assert meta["held_out_codes"]["by_time"] == avatar.code_keys.keys_time  # the inside's choice, and its measure
    assert float(avatar.outside.neutral_texture.abs().sum()) > 0  # personalised on the scan
    assert meta["view_range"]["yaw_deg"] == [-180.0, 180.0] and avatar.card.turntable_sweep_deg() == 0.0  # round
    assert meta["captured_view_range"] == json.loads((out / "parts" / "inside" / "avatar.json").read_text())[
        "view_range"]
    lrs = [json.loads((out / "parts" / p / "avatar.json").read_text())["provenance"]["config"]["lr"]
           for p in ("inside", "outside")]
    assert lrs == ["0.01", str(PERSONALIZE_LR)]  # --lr is the inside's; the outside personalises at the prior's
    # the outside fine-tunes the prior's per-texel maps alone (WHOLE_OUTSIDE_TUNE): its shared weights are the prior's
    assert json.loads((out / "parts" / "outside" / "avatar.json").read_text())["prior"]["tune"] == "texel"
    texels = {n for n, p in small.named_parameters() if any(p is q for q in small.texel_parameters())}
    mine = dict(avatar.outside.named_parameters())
    changed = {n for n, p in small.named_parameters() if not torch.equal(p.detach(), mine[n].detach())}
    assert changed and changed <= texels, changed - texels
    records = [json.loads(line) for line in (out / "progress.jsonl").read_text().splitlines()]
    assert records[0]["stage"] == "inside" and records[-1]["stage"] == "outside" and records[-1]["step"] == 5
    assert all(b["elapsed_s"] >= a["elapsed_s"] for a, b in itertools.pairwise(records))
    split = load_split(scan, "train")  # a training frame's view is the inside's, as its own folder renders it
    camera, controls = frame_camera(split, split.frames[0]), split.frames[0].controls
    inside, _ = load_avatar(out / "parts" / "inside")
    np.testing.assert_array_equal(render_image(avatar, camera, controls, RenderOptions(buffers=()))["rgb"],
                                  render_image(inside, camera, controls, RenderOptions(buffers=()))["rgb"])

    for f in [out / "avatar.json", *out.glob("weights-*.safetensors")]:  # as if stopped in the outside's turn
        f.unlink()
    for f in (out / "parts" / "outside").iterdir():
        f.unlink()
    assert main(["train", str(scan), "--out", str(out), "--steps", "4", "--resume"]) == 0
    assert f"the universal prior {prior.resolve()} personalised" in capsys.readouterr().out
    assert json.loads((out / "avatar.json").read_text())["model"] == "whole"
    assert main(["train", str(scan), "--out", str(out), "--steps", "12", "--resume"]) == 0  # finished: more of both
    made = json.loads((out / "avatar.json").read_text())["provenance"]
    assert (made["inside"]["steps"], made["outside"]["steps"], made["steps"]) == (11, 1, 12)


def test_the_outside_renders_at_most_the_samples_it_trained_with(whole):
    """From behind (every ray the outside's), a render at four times the outside's samples is the outside's own
    render at its samples, bit for bit (an outside of 8^3 voxels, where more samples would change the pixels); at
    fewer samples than its own, it renders at those."""
    from dataclasses import replace

    from models.avatars.quality import Quality

    torch.manual_seed(3)
    outside = PriorAvatar.for_capture(whole.head_model, 1, np.full(3, 0.7, np.float32), (), None,
                                      replace(SMALL, grid=8, voxels=8))
    wide = WholeHeadAvatar(whole.inside, outside).eval()
    cam, _, _, w = rays_and_weights(wide, 180.0)
    assert torch.all(w == 0.0)
    own = outside.cfg.samples
    at = lambda avatar, n: render_image(avatar, cam, Controls(), RenderOptions(buffers=(), quality=Quality(1.0, n)))
    assert not np.array_equal(at(outside, 4 * own)["rgb"], at(outside, own)["rgb"])
    np.testing.assert_array_equal(at(wide, 4 * own)["rgb"], at(outside, own)["rgb"])
    np.testing.assert_array_equal(at(wide, own // 2)["rgb"], at(outside, own // 2)["rgb"])


def test_the_outside_decoded_ahead_renders_as_decoded_after(whole):
    """Where both parts render a frame, the outside decoded on its own thread beside the inside gives the frame bit
    for bit, and is decoded once a frame either way (its render finds the decode made)."""
    cam, _, _, w = rays_and_weights(whole, CONE_DEG + 20.0)
    assert bool((w > 0.0).any()) and bool((w < 1.0).any())  # both parts render
    decodes = []
    own = whole.outside.decode

    def counted(*args, **kwargs):
        decodes.append(threading.current_thread().name)
        return own(*args, **kwargs)

    whole.outside.decode = counted
    try:
        images = []
        for ahead in (True, False):
            whole.decode_ahead = ahead
            images.append(render_image(whole, cam, Controls(), RenderOptions(buffers=()))["rgb"])
    finally:
        whole.decode_ahead = True
        del whole.outside.decode
    np.testing.assert_array_equal(images[0], images[1])
    assert len(decodes) == 2 and decodes[0].startswith("whole-outside") and decodes[1] == "MainThread", decodes


def test_the_outsides_boxes_are_shown_no_longer_than_three_times_their_width():
    """The slabs behind a head: a prior whose decoder asks every box to grow e^2 (7.4) times along one axis and
    0.8 times along another is shown that way on its own (`--model prior`: its shoulders in the video's views), and
    within OUTSIDE_STRETCH (3 x 0.8 = 2.4 times) as a whole head's outside; training's decode keeps what it asks."""
    head = load_builtin()
    inside = PrimitivesAvatar.for_capture(head, 4, np.zeros(3, np.float32), (), None,
                                          PrimitivesConfig(grid=8, voxels=2, width=16))
    alone = PriorAvatar.for_capture(head, 1, np.zeros(3, np.float32), (), None, SMALL)
    with torch.no_grad():
        alone.decoder.offsets.weight.zero_()
        alone.decoder.offsets.bias.zero_()
        alone.decoder.offsets.bias[6:9] = torch.tensor([2.0, 0.0, math.log(0.8)])
    geo = alone.geometry(Controls())
    eye = torch.tensor([0.0, 0.0, 1.0])

    def largest(avatar, training=False):
        with torch.no_grad():
            prims, _ = avatar.decode(geo, avatar.codes(None), eye, training=training)
        return float((prims.half_sizes / avatar.layout_half[:, None]).max())

    assert largest(alone) == pytest.approx(math.exp(2.0), rel=1e-5)
    outside = WholeHeadAvatar(inside, alone).outside
    assert OUTSIDE_STRETCH == 3.0 and largest(outside) == pytest.approx(3.0 * 0.8, rel=1e-5)
    assert largest(outside, training=True) == pytest.approx(math.exp(2.0), rel=1e-5)


def test_the_outside_stops_its_rays_at_a_hundredth_of_their_light(whole):
    """The outside's display stops a ray once less than OUTSIDE_STOP_BELOW of its light gets through, where the
    inside keeps its own threshold: from behind (every ray the outside's), the frame is within that share of the
    colour range of the outside's marched to 1e-4."""
    from dataclasses import replace

    assert whole.inside.cfg.stop_below == PrimitivesConfig().stop_below < OUTSIDE_STOP_BELOW
    assert whole.outside.cfg.stop_below == OUTSIDE_STOP_BELOW
    cam, _, _, w = rays_and_weights(whole, 180.0)
    assert torch.all(w == 0.0)
    frame = render_image(whole, cam, Controls(), RenderOptions(buffers=()))["rgb"]
    kept = whole.outside.cfg
    whole.outside.cfg = replace(kept, stop_below=1e-4)
    try:
        deep = render_image(whole.outside, cam, Controls(), RenderOptions(buffers=()))["rgb"]
    finally:
        whole.outside.cfg = kept
    assert 0.0 < np.abs(frame - deep).max() <= OUTSIDE_STOP_BELOW + 1e-6  # 0.003 here: rays did stop sooner


def test_the_outsides_neck_ends_in_a_soft_edge_below_a_body():
    """Where the inside has a body layer (a video's shoulders), a whole head's outside shows its density times a
    smooth step down the neck in the head's own frame (all of it to NECK_FADE_M[0] below the eyes, none from
    NECK_FADE_M[1]), where the head is turned and nodded too; the prior on its own, training's decode and a whole head
    with no body keep every voxel's. Each voxel's point made one by one here, from its box."""
    from dataclasses import replace

    from models.avatars.primitives.seen import NECK_FADE_M, eye_height_m

    head = load_builtin()
    inside = PrimitivesAvatar.for_capture(head, 4, np.zeros(3, np.float32), (), None,
                                          PrimitivesConfig(grid=8, voxels=2, width=16, body_layer=True))
    torch.manual_seed(3)
    alone = PriorAvatar.for_capture(head, 1, np.zeros(3, np.float32), (), None, replace(SMALL, voxels=4))
    eyes = eye_height_m(head)
    joints = head.J_regressor @ head.template
    assert eyes == pytest.approx(0.5 * (joints[3, 1] + joints[4, 1]))  # eye_l, eye_r
    controls = Controls(neck=np.array([0.3, 0.5, 0.1], np.float32), translation=np.array([0.01, -0.02, 0.03]))
    geo = alone.geometry(controls)
    eye = torch.tensor([0.0, 0.0, 1.0])
    with torch.no_grad():
        own, _ = alone.decode(geo, alone.codes(None), eye)
        torch.manual_seed(4)  # training's decode draws its expression code
        trained, _ = alone.decode(geo, alone.codes(None), eye, training=True)
        outside = WholeHeadAvatar(inside, alone).outside
        shown, _ = outside.decode(geo, outside.codes(None), eye)
        torch.manual_seed(4)
        taught, _ = outside.decode(geo, outside.codes(None), eye, training=True)
    M = shown.density.shape[1]
    assert torch.equal(taught.density, trained.density)
    expected = torch.empty_like(shown.density)
    R, t = geo.rotation.double(), geo.translation.double()
    for p in range(len(shown.centres)):
        for z, y, x in itertools.product(range(M), repeat=3):
            local = torch.tensor([x, y, z], dtype=torch.float64) * 2.0 / (M - 1) - 1.0
            point = shown.centres[p].double() + shown.rotations[p].double() @ (shown.half_sizes[p].double() * local)
            height = float((R.T @ (point - t))[1])
            s = min(max((height - (eyes - NECK_FADE_M[1])) / (NECK_FADE_M[1] - NECK_FADE_M[0]), 0.0), 1.0)
            expected[p, z, y, x] = s * s * (3.0 - 2.0 * s)
    # The outside's shown boxes are within OUTSIDE_STRETCH, the prior's own as decoded: the same density grids
    # before the fade, so the fade is their ratio.
    torch.testing.assert_close(shown.density, own.density * expected, rtol=1e-5, atol=1e-6)
    assert float((expected == 1).float().mean()) > 0.5 and float(expected.min()) < 0.3  # the head kept, the neck not
    assert 0 < int(((expected > 0) & (expected < 1)).sum())  # a soft edge, not a cut
    bodiless = PrimitivesAvatar.for_capture(head, 4, np.zeros(3, np.float32), (), None,
                                            PrimitivesConfig(grid=8, voxels=2, width=16))
    with torch.no_grad():
        kept, _ = WholeHeadAvatar(bodiless, alone).outside.decode(geo, alone.codes(None), eye)
    torch.testing.assert_close(kept.density, own.density, rtol=0, atol=0)
