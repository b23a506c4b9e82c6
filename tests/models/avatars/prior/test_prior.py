"""The universal prior: its conditioning maps checked by hand, its encoders' start and gradients, the masked
gaze, and training in two gloo processes against one."""

from __future__ import annotations

import contextlib
import json
import socket
from pathlib import Path

import numpy as np
import pytest
import torch

from models.avatars.primitives.chart import GEOMETRY_SCALE_M, chart_sampler, eye_cells, geometry_map, texel_points
from models.avatars.prior.avatar import PriorAvatar, PriorConfig
from models.avatars.prior.maps import (
    CROWN_ABOVE_EYES_M,
    HAIR_MIN_SHARE,
    NAPE_BELOW_EYES_M,
    average_texture,
    eye_heights,
    hair_colour,
    texture_map,
)
from models.avatars.rendering import render_image
from models.capture.synthetic import SynthConfig, synthesize
from models.head.controls import Controls
from models.head.sources import load_builtin
from render.gl.raster import Rasterizer
from tests.conftest import DEMO

SMALL = PriorConfig(grid=8, voxels=2, width=16, latent=4)


@pytest.fixture(scope="module")
def builtin():
    return load_builtin()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory, gl) -> Path:
    """Two identities of the built-in head, 10 frames of 32 px each."""
    root = tmp_path_factory.mktemp("corpus")
    for k in (1, 2):
        synthesize(SynthConfig(scene="ambient", frames=10, size=32, identity=k, out=root / f"id{k:04d}"),
                   load_builtin(), gl)
    return root


def test_geometry_map_is_the_texels_points(builtin):
    s = chart_sampler(builtin, 16)
    v = torch.as_tensor(builtin.template, dtype=torch.float64)
    tris = torch.as_tensor(np.asarray(builtin.triangles))
    g = geometry_map(s, tris, v).reshape(3, -1).T
    # a texel's point is its triangle's barycentric point, about the template's centre in decimetres
    k = int(np.nonzero(s.valid)[0][len(np.nonzero(s.valid)[0]) // 2])
    corners = builtin.template[builtin.triangles[s.triangles[k]]]
    expect = (s.bary[k] @ corners - s.centre) / GEOMETRY_SCALE_M
    np.testing.assert_allclose(g[k].numpy(), expect, atol=1e-5)
    # moving the mesh 1 cm along x moves every texel on the head by 0.1 in the map's x, and none off it
    g2 = geometry_map(s, tris, v + torch.tensor([0.01, 0.0, 0.0], dtype=torch.float64)).reshape(3, -1).T
    d = (g2 - g).numpy()
    np.testing.assert_allclose(d[s.valid], np.tile([0.1, 0.0, 0.0], (int(s.valid.sum()), 1)), atol=1e-9)
    assert np.abs(d[~s.valid]).max(initial=0.0) == 0.0
    assert s.valid.mean() > 0.6  # most of the chart's rays leave the head


def test_texture_map_unprojects_what_the_camera_sees(builtin, gl):
    """A uniform image unprojects to its colour wherever a frontal camera sees the head, and to weight 0 on the
    back of the head."""
    from render.camera import framing_camera

    s = chart_sampler(builtin, 32)
    v = torch.as_tensor(builtin.template, dtype=torch.float32)
    cam = framing_camera(builtin.template, width_px=64, height_px=64)
    r = Rasterizer(gl)
    raster = r.rasterize(builtin.template, builtin.triangles, cam)
    r.release()
    image = np.ones((64, 64, 3), np.float32) * np.array([0.2, 0.5, 0.7], np.float32)
    rgb, w = texture_map(s, torch.as_tensor(np.asarray(builtin.triangles)), v, cam, image, raster)
    seen = w > 0
    assert 0.15 < seen.mean() < 0.6, seen.mean()
    np.testing.assert_allclose(rgb[seen], np.tile([0.2, 0.5, 0.7], (int(seen.sum()), 1)), atol=1e-6)
    points = texel_points(s, torch.as_tensor(np.asarray(builtin.triangles)), v).numpy().reshape(32, 32, 3)
    behind = (points[..., 2] < s.centre[2] - 0.03) & s.valid.reshape(32, 32)
    assert behind.any() and not seen[behind].any()  # the back of the head is never seen from the front


def test_an_untrained_prior_decodes_as_its_shared_decoder_and_learns_identity(builtin):
    torch.manual_seed(0)
    avatar = PriorAvatar(builtin, SMALL, 1, np.full(3, 0.5, np.float32))
    geo = avatar.geometry(Controls())
    S = SMALL.grid * SMALL.voxels
    a = avatar.decode(geo, avatar.codes(None), torch.tensor([0.0, 0.0, 1.0]))[0]
    avatar.personalize(torch.randn(1, 3, S, S), torch.randn(1, 3, S, S))
    b = avatar.decode(geo, avatar.codes(None), torch.tensor([0.0, 0.0, 1.0]))[0]
    torch.testing.assert_close(a.density, b.density)  # the identity heads start at zero
    # a loss on the decode reaches both encoders
    avatar.train()
    prims = avatar.decode(geo, avatar.codes(None), torch.tensor([0.0, 0.0, 1.0]), training=True)[0]
    prims.colour.square().mean().backward()
    assert all(h.weight.grad is not None and h.weight.grad.abs().sum() > 0 for h in avatar.identity_encoder.heads)
    assert avatar.expression_encoder.mean.weight.grad.abs().sum() > 0


def test_a_steps_frames_share_one_pass_of_the_identity_encoder(builtin):
    """Within a training step the person's bias maps are made once for all its frames: the same loss and the same
    gradients as with E_id run for each frame, and E_id called once (twice without the step)."""
    torch.manual_seed(0)
    avatar = PriorAvatar(builtin, SMALL, 1, np.full(3, 0.5, np.float32))
    S = SMALL.grid * SMALL.voxels
    avatar.personalize(torch.randn(1, 3, S, S), torch.randn(1, 3, S, S))
    with torch.no_grad():  # the identity heads start at zero: give them weights, so that E_id reaches the loss
        for h in avatar.identity_encoder.heads:
            h.weight.normal_(0, 0.1)
    avatar.train()
    geos = [avatar.geometry(Controls()), avatar.geometry(Controls(jaw=np.array([0.3, 0.0, 0.0], np.float32)))]
    calls = []
    hook = avatar.identity_encoder.register_forward_hook(lambda *_: calls.append(1))

    def loss_and_grads(step: bool) -> tuple[torch.Tensor, list[torch.Tensor]]:
        avatar.zero_grad()
        calls.clear()
        with avatar.training_step() if step else contextlib.nullcontext():
            total = sum(avatar.decode(g, avatar.codes(None), torch.tensor([0.0, 0.0, 1.0]), training=True)[0]
                        .colour.square().mean() for g in geos)
        total.backward()
        return total.detach(), [p.grad.clone() for p in avatar.identity_encoder.parameters() if p.grad is not None]

    torch.manual_seed(1)
    each, grads_each = loss_and_grads(step=False)
    assert len(calls) == 2
    torch.manual_seed(1)
    shared, grads_shared = loss_and_grads(step=True)
    assert len(calls) == 1
    hook.remove()
    torch.testing.assert_close(shared, each)
    assert len(grads_shared) == len(grads_each) > 0 and any(g.abs().sum() > 0 for g in grads_each)
    for a, b in zip(grads_shared, grads_each, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7)


def test_tuning_the_texels_alone_changes_only_the_texels_a_loss_reached(builtin):
    """`tune texel` (a whole head's outside): a step on one primitive's colour changes the decoder's per-texel bias
    maps alone, and of the slab's only that primitive's M x M texels (its row 0, column 3 on the K x K chart); every
    other weight, the encoders' and the shared convolutions', and every other texel stay as the prior has them. The
    choice is the config's: an avatar made from its meta (a resumed run) tunes the same."""
    torch.manual_seed(0)
    avatar = PriorAvatar(builtin, SMALL, 1, np.full(3, 0.5, np.float32))
    S, M = SMALL.grid * SMALL.voxels, SMALL.voxels
    avatar.personalize(torch.randn(1, 3, S, S), torch.randn(1, 3, S, S))
    avatar.tune_only("texel")
    trained = {n for n, p in avatar.named_parameters() if p.requires_grad}
    assert trained == {f"decoder.biases.{k}" for k in range(len(avatar.decoder.biases))} | {"decoder.slab_bias"}
    before = {n: p.detach().clone() for n, p in avatar.named_parameters()}
    opt = torch.optim.Adam(avatar.parameters(), lr=1e-2)
    avatar.train()
    prims = avatar.decode(avatar.geometry(Controls()), avatar.codes(None), torch.tensor([0.0, 0.0, 1.0]),
                          training=True)[0]
    (prims.colour[3] - 1.0).square().mean().backward()
    opt.step()
    for n, p in avatar.named_parameters():
        if n not in trained:
            torch.testing.assert_close(p.detach(), before[n], rtol=0, atol=0)
    moved = (avatar.decoder.slab_bias.detach() != before["decoder.slab_bias"]).any(0)
    expect = torch.zeros(S, S, dtype=torch.bool)
    expect[0:M, 3 * M:4 * M] = True
    assert torch.equal(moved, expect)
    again = PriorAvatar.from_meta(builtin, {**avatar.meta(), "frames": 1, "background": [0.5] * 3})
    assert again.cfg.tune == "texel"
    assert {n for n, p in again.named_parameters() if p.requires_grad} == trained


def test_expression_maps_see_the_jaw_not_the_head_turn(builtin):
    avatar = PriorAvatar(builtin, SMALL, 1, np.full(3, 0.5, np.float32))
    turned = avatar.geometry(Controls(root=np.array([0.0, 0.5, 0.0], np.float32)))
    assert float(turned.expression.abs().max()) < 1e-4  # a rigid turn is not an expression
    opened = avatar.geometry(Controls(jaw=np.array([0.3, 0.0, 0.0], np.float32)))
    assert float(opened.expression.abs().max()) > 0.05  # more than 5 mm somewhere: the chin moved
    # The rigid pose is taken out exactly (the root joint's), not fitted to the whole mesh: the top of the head stays
    # where the neutral has it while the jaw opens and the head turns (a fit took in part of the jaw: 0.027 there).
    both = avatar.geometry(Controls(root=np.array([0.0, 0.5, 0.0], np.float32), jaw=np.array([0.3, 0.0, 0.0],
                                                                                            np.float32)))
    neutral = avatar.neutral_geometry_of(np.zeros(0, np.float32))[0]
    top = neutral[1] > 0.6 * neutral[1].max()
    assert int(top.sum()) > 20 and float(both.expression[0][:, top].abs().max()) < 1e-5
    torch.testing.assert_close(both.expression, opened.expression, rtol=0, atol=1e-5)


def test_gaze_reaches_only_the_eyes_cells(builtin):
    mask = eye_cells(builtin, 64)
    assert mask.shape == (1, 1, 8, 8)
    assert 0 < mask.sum() < 0.4 * 64  # the eyes and their neighbours, not the head


def _train(rank: int, world: int, corpus: str, out: str, port: int, steps: int) -> None:
    import torch.distributed as dist

    from models.training.prior import PriorTrainConfig, prepare_prior
    from render.gl.context import GLContext

    torch.set_num_threads(1)
    if world > 1:
        dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    gl = GLContext.headless()
    cfg = PriorTrainConfig(corpus=Path(corpus), out=Path(out), steps=steps, frames_per_step=4, rays_per_frame=64,
                           grid=8, voxels=2, width=16)
    trainer = prepare_prior(cfg, gl, rank, world)
    torch.save({k: v.detach().clone() for k, v in trainer.avatar.state_dict().items()}, Path(out) / "init.pt")
    losses = [trainer.train_step(k / steps)["loss"] for k in range(steps)]
    weights = {k: v.detach().clone() for k, v in trainer.avatar.state_dict().items()}
    torch.save(weights, Path(out) / f"weights-rank{rank}.pt")
    (Path(out) / f"losses-rank{rank}.json").write_text(json.dumps(losses))
    if world > 1:
        dist.destroy_process_group()
    gl.release()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_gloo_processes_take_the_step_one_takes(corpus, tmp_path):
    """DistributedDataParallel over two CPU processes: their weights stay identical, and the loss of each step (the
    mean of the two halves) and the weights after three steps match one process on the same samples."""
    import torch.multiprocessing as mp

    one, two = tmp_path / "one", tmp_path / "two"
    one.mkdir()
    two.mkdir()
    _train(0, 1, str(corpus), str(one), 0, 3)
    mp.spawn(_train, args=(2, str(corpus), str(two), _free_port(), 3), nprocs=2, join=True)
    w0, w1 = (torch.load(two / f"weights-rank{r}.pt") for r in (0, 1))
    single = torch.load(one / "weights-rank0.pt")
    for k in single:
        assert torch.equal(w0[k], w1[k]), k
        torch.testing.assert_close(w0[k], single[k], atol=2e-5, rtol=1e-4)
    halves = [json.loads((two / f"losses-rank{r}.json").read_text()) for r in (0, 1)]
    whole = json.loads((one / "losses-rank0.json").read_text())
    np.testing.assert_allclose(0.5 * (np.array(halves[0]) + np.array(halves[1])), whole, rtol=1e-4)
    init = torch.load(one / "init.pt")
    assert sum(float((single[k] - init[k]).abs().sum()) for k in init) > 0  # the three steps moved the weights


def _torchrun_like(rank: int, world: int, port: int, out: str) -> None:
    """What prior-train does first in each process torchrun starts: the group from torchrun's environment, then a
    CPU broadcast (rank 0's clock) and a gradient-sized all-reduce."""
    import os

    import torch.distributed as dist

    from models.training.prior import distributed_from_env, process_device

    os.environ.update(RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE=str(world), MASTER_ADDR="127.0.0.1",
                      MASTER_PORT=str(port))
    got = distributed_from_env("cpu")
    clock = torch.tensor([10.0 + rank], dtype=torch.float64)
    dist.broadcast(clock, 0)
    total = torch.tensor([float(rank + 1)])
    dist.all_reduce(total)
    (Path(out) / f"rank{rank}.json").write_text(json.dumps(
        {"got": list(got), "backend": dist.get_backend(), "device": str(process_device("cpu")),
         "clock": float(clock), "total": float(total)}))
    dist.destroy_process_group()


def test_processes_started_as_torchrun_starts_them_form_one_group(tmp_path):
    """prior-train's own start under torchrun (RANK, LOCAL_RANK, WORLD_SIZE, MASTER_* in the environment): each
    process finds its rank in a gloo group of two, rank 0's clock reaches both (so they stop on one step), and an
    all-reduce sums 1 + 2."""
    import torch.multiprocessing as mp

    mp.spawn(_torchrun_like, args=(2, _free_port(), str(tmp_path)), nprocs=2, join=True)
    for rank in (0, 1):
        r = json.loads((tmp_path / f"rank{rank}.json").read_text())
        assert r == {"got": [rank, 2], "backend": "gloo", "device": "cpu", "clock": 10.0, "total": 3.0}


def test_each_gpu_process_takes_its_own_gpu():
    """NCCL needs one GPU a process: torchrun's LOCAL_RANK picks it, and a node with too few GPUs is told so (no GPU
    here: the device count is given)."""
    from models.device import DeviceError
    from models.training.prior import process_device

    assert [process_device("cuda", {"LOCAL_RANK": str(k)}, lambda: 4).index for k in range(4)] == [0, 1, 2, 3]
    with pytest.raises(DeviceError, match="process 2 of this node needs GPU 2, and torch sees 2"):
        process_device("cuda", {"LOCAL_RANK": "2"}, lambda: 2)


def test_corpus_prior_and_personalize_from_the_command_line(tmp_path, capsys):
    """corpus (two people, two views), prior-train (three steps), personalize a held-out person (seed 1000): an
    ordinary avatar folder whose neutral maps are the person's, that renders; and the corpus refuses held-out
    seeds."""
    from app.cli import main
    from models.avatars.registry import load_avatar

    corpus, prior, scan, person = (tmp_path / n for n in ("corpus", "prior", "scan", "person"))
    assert main(["corpus", "--identities", "2", "--frames", "10", "--views", "2", "--size", "32",
                 "--out", str(corpus)]) == 0
    split = json.loads((corpus / "id0001" / "transforms_train.json").read_text())
    yaws = [round(f["script"]["camera_yaw_deg"] - split["frames"][0]["script"]["camera_yaw_deg"], 3)
            for f in split["frames"][:2]]
    assert yaws == [0.0, 180.0]  # each script frame from the rig's two cameras, in front and behind
    assert main(["corpus", "--first", "999", "--identities", "2", "--out", str(tmp_path / "c2")]) == 2
    assert "held-out" in capsys.readouterr().err
    small = ["--grid", "8", "--voxels", "2", "--width", "16", "--rays-per-frame", "64", "--frames-per-step", "2"]
    assert main(["prior-train", str(corpus), "--out", str(prior), "--steps", "2", *small,
                 "--model-options", "opacity_window=true", "keep_size=true"]) == 0
    assert "reading the corpus: 2/2 identities" in capsys.readouterr().err  # minutes on a large corpus: shown
    assert main(["prior-train", str(corpus), "--out", str(prior), "--steps", "3", "--resume",
                 "--model-options", "opacity_window=false"]) == 2
    assert "--model-options with --resume" in capsys.readouterr().err
    assert main(["prior-train", str(corpus), "--out", str(prior), "--steps", "3", "--resume"]) == 0
    prior_meta = json.loads((prior / "avatar.json").read_text())
    assert prior_meta["step"] == 3 and prior_meta["prior"]["opacity_window"] and prior_meta["prior"]["keep_size"]
    assert prior_meta["prior"]["grid"] == 8  # resumed with the sizes it was begun with, not the defaults
    assert main(["synth", "--identity", "1000", "--frames", "10", "--size", "32", "--scene", "ambient",
                 "--out", str(scan)]) == 0
    assert main(["personalize", str(scan), "--prior", str(DEMO), "--out", str(person)]) == 2
    assert "not a universal prior" in capsys.readouterr().err and not person.exists()
    assert main(["personalize", str(scan), "--prior", str(prior), "--out", str(person), "--steps", "2"]) == 0
    avatar, meta = load_avatar(person)
    assert meta["model"] == "prior" and meta["provenance"]["steps"] == 2
    assert meta["prior"]["opacity_window"] and meta["prior"]["keep_size"]  # the person's avatar has the prior's
    assert meta["view_range"]["yaw_deg"] == [-180.0, 180.0]  # the prior saw heads all round: turntables go round
    assert float(avatar.neutral_texture.abs().sum()) > 0 and float(avatar.neutral_geometry.abs().sum()) > 0
    prior_avatar, _ = load_avatar(prior)
    assert float(prior_avatar.neutral_texture.abs().sum()) == 0  # the prior itself is no one
    from render.camera import framing_camera
    from render.gl.context import GLContext

    gl = GLContext.headless()
    img = render_image(avatar, framing_camera(avatar.card.rest_vertices(), width_px=32, height_px=32), Controls(),
                       rasterizer=Rasterizer(gl))["rgb"]
    gl.release()
    assert np.isfinite(img).all() and img.shape == (32, 32, 3)


PRIOR = Path(__file__).resolve().parents[4] / "resources" / "prior"


@pytest.mark.gl
def test_one_persons_expression_drives_another(gl):
    """The shared expression space (the seed's Fig. 9) on the shipped prior: the code of person A's open jaw is
    person B's (Delta G takes the identity out), and driving B with it opens B's mouth: the render changes about the
    lips far more than on the forehead."""
    from models.capture.synthetic import identity_coefficients

    if not (PRIOR / "avatar.json").is_file():
        pytest.skip(f"no shipped prior at {PRIOR}")
    from models.avatars.registry import load_avatar
    from render.camera import framing_camera

    avatar, _ = load_avatar(PRIOR)
    head = avatar.head_model
    a_shape, b_shape = identity_coefficients(head, 1001), identity_coefficients(head, 1002)
    jaw = np.array([0.35, 0.0, 0.0], np.float32)

    def code(controls):
        g = avatar.geometry(controls)
        return avatar.expression_encoder(torch.zeros_like(g.expression), g.expression)[0]

    with torch.no_grad():
        a_open, b_open, b_rest = (code(Controls(shape=a_shape, jaw=jaw)), code(Controls(shape=b_shape, jaw=jaw)),
                                  code(Controls(shape=b_shape)))
    # the identity moves the code by a small part of what the jaw does (0.12 of it on the shipped prior)
    assert float((a_open - b_open).norm()) < 0.25 * float((b_open - b_rest).norm())
    avatar.personalize(torch.zeros(1, 3, *avatar.neutral_texture.shape[2:]), avatar.neutral_geometry_of(b_shape))
    cam = framing_camera(head.template, width_px=96, height_px=96)
    r = Rasterizer(gl)
    rest = render_image(avatar, cam, Controls(shape=b_shape), rasterizer=r)["rgb"]
    opened = render_image(avatar, cam, Controls(shape=b_shape, jaw=jaw), rasterizer=r)["rgb"]
    r.release()
    lips = head.landmarks.as_barycentric(head.triangles)
    ids, bary = lips
    lm = (head.template[ids] * bary[..., None]).sum(1)
    px = np.stack([(cam.projection @ cam.view @ np.r_[p, 1.0]) for p in lm])
    xy = np.stack([(px[:, 0] / px[:, 3] + 1) / 2 * 96, (1 - px[:, 1] / px[:, 3]) / 2 * 96], 1)
    mouth, brow = xy[48:68], xy[17:27]
    box = lambda pts, pad: (slice(max(0, int(pts[:, 1].min()) - pad), int(pts[:, 1].max()) + pad + 1),
                            slice(max(0, int(pts[:, 0].min()) - pad), int(pts[:, 0].max()) + pad + 1))
    change = np.abs(opened - rest).mean(-1)
    near_mouth = change[box(mouth, 3)].mean()
    forehead = change[box(brow - [0, 10], 2)].mean()
    # measured on the shipped prior: 0.020 about the lips (the box holds cheek and chin too), 0.0016 on the forehead
    # (the first shipped prior, of 24 bald synthetic people, gave 0.011 and 1e-5)
    assert near_mouth > 0.005 and near_mouth > 10 * forehead, (near_mouth, forehead)


def test_a_real_scan_personalizes_over_its_room(tmp_path, one_second_scan, capsys):
    """A second of a real video tracked with the built-in head is a scan: personalize composites the person over
    the video's room (the plate, as `train` does), and the avatar renders the capture camera's view over it."""
    from app.cli import main
    from models.avatars.registry import load_avatar
    from models.capture.dataset import load_split
    from models.capture.frames import frame_camera

    if not (PRIOR / "avatar.json").is_file():
        pytest.skip(f"no shipped prior at {PRIOR}")
    scan, out = one_second_scan, tmp_path / "me"
    assert main(["personalize", str(scan), "--prior", str(PRIOR), "--out", str(out), "--steps", "2"]) == 0
    avatar, _ = load_avatar(out)
    split = load_split(scan, "test")
    camera = frame_camera(split, split.frames[0])
    plate = avatar.plate.for_camera(camera)
    assert plate is not None  # the room was kept with the weights
    image = render_image(avatar, camera, split.frames[0].controls, rasterizer=None)["rgb"]
    corner = image[:4, :4].reshape(-1, 3)  # no person up there: the room shows as the plate has it
    np.testing.assert_allclose(corner, plate.reshape(64, 64, 3)[:4, :4].reshape(-1, 3).numpy(), atol=0.02)


def test_a_tracked_video_joins_the_corpus_and_train_starts_from_the_prior(tmp_path, corpus, one_second_scan, gl,
                                                                          capsys):
    """A real person (a second of video tracked with the built-in head) joins the synthetic corpus with
    `prior-train --people`: their frames composite over their own room (the plate kept in their frames, none kept
    by the prior); a person of another head model is refused by name; `train` on a tracked video personalises the
    prior and says so, `--from-scratch` trains the primitives from nothing."""
    from app.cli import main
    from models.avatars.registry import load_avatar
    from models.capture.dataset import load_split
    from models.capture.frames import background_plate
    from models.training.configs import PriorTrainConfig
    from models.training.prior import prepare_prior

    scan, prior, other = one_second_scan, tmp_path / "prior", tmp_path / "demo_person"
    small = ["--grid", "8", "--voxels", "2", "--width", "16", "--rays-per-frame", "64", "--frames-per-step", "2"]
    assert main(["prior-train", str(corpus), "--people", str(scan), "--out", str(prior), "--steps", "2", *small]) == 0
    meta = json.loads((prior / "avatar.json").read_text())
    assert meta["corpus"]["identities"] == ["id0001", "id0002", "real_person"]
    trainer = prepare_prior(PriorTrainConfig(corpus=corpus, people=(scan,), out=tmp_path / "p2", grid=8, voxels=2,
                                             width=16), gl)
    room, _ = background_plate(load_split(scan, "train"))
    real = trainer.identities[-1].frames
    assert real.plate is not None and torch.equal(real.plate, torch.as_tensor(room, dtype=torch.float32).reshape(-1, 3))
    assert trainer.identities[0].frames.plate is None and trainer.avatar.plate.image is None  # no one's room kept

    assert main(["synth", "--head", "demo", "--frames", "10", "--size", "32", "--out", str(other)]) == 0
    capsys.readouterr()
    assert main(["prior-train", str(corpus), "--people", str(other), "--out", str(tmp_path / "p3"), "--steps", "1",
                 *small]) == 2
    err = capsys.readouterr().err
    assert f"{other}: its head model is demo" in err and "builtin" in err and not (tmp_path / "p3").exists()

    assert main(["train", str(scan), "--prior", str(prior), "--out", str(tmp_path / "a"), "--steps", "1"]) == 0
    out = capsys.readouterr().out
    assert f"from the universal prior {prior} (3 people of the builtin head)" in out
    personal, meta = load_avatar(tmp_path / "a")
    assert meta["model"] == "prior" and float(personal.neutral_texture.abs().sum()) > 0
    assert meta["provenance"]["config"]["lr"] == "0.001"  # the prior's fine-tuning rate, not from scratch's
    assert main(["train", str(scan), "--out", str(tmp_path / "a"), "--steps", "2", "--resume"]) == 0
    meta = json.loads((tmp_path / "a" / "avatar.json").read_text())
    assert meta["model"] == "prior" and meta["provenance"]["steps"] == 2
    assert meta["view_range"]["yaw_deg"] == [-180.0, 180.0]  # resumed, it still turns all the way round
    assert main(["train", str(scan), "--prior", str(prior), "--from-scratch", "--out", str(tmp_path / "b"),
                 "--steps", "1"]) == 0
    assert "from scratch (--from-scratch)" in capsys.readouterr().out
    assert json.loads((tmp_path / "b" / "avatar.json").read_text())["model"] == "primitives"
    # Of another head model (the demo's, ICT's identity): the same weights on its primitives (load_prior)
    assert main(["train", str(other), "--model", "prior", "--prior", str(prior), "--out", str(tmp_path / "c"),
                 "--steps", "1"]) == 0
    assert "on the demo head the capture is tracked with" in capsys.readouterr().out
    across, meta = load_avatar(tmp_path / "c")
    prior_avatar, _ = load_avatar(prior)
    assert meta["head_model"] == "demo" and across.head_model.name != prior_avatar.head_model.name
    layout_of = PriorAvatar(across.head_model, across.cfg, 1, np.zeros(3, np.float32)).layout_triangles
    assert torch.equal(across.layout_triangles, layout_of)  # where the demo head's primitives sit, not the prior's
    ref, got = prior_avatar.decoder.state_dict(), across.decoder.state_dict()  # the prior's weights, one step on
    step = max(float((got[k] - v).abs().max()) for k, v in ref.items() if v.is_floating_point())
    fresh = PriorAvatar(across.head_model, across.cfg, 1, np.zeros(3, np.float32)).decoder.state_dict()
    assert step <= 2e-3 < 0.05 < max(float((fresh[k] - v).abs().max()) for k, v in ref.items() if v.is_floating_point())


def test_train_starts_from_the_prior_only_where_it_fits(tmp_path, monkeypatch):
    """training_start: a prior asked for (`--model prior`, `--model whole`, `--prior`) is personalised, and must be a
    universal prior (of any head model: load_prior); left to the default, a tracked video starts as VIDEO_START
    says; a synthetic capture, another model or --from-scratch train from nothing; each with its reason."""
    from models.avatars import registry
    from models.avatars.checkpoint import CheckpointError
    from models.avatars.registry import SHIPPED_PRIOR, training_start

    if not (SHIPPED_PRIOR / "avatar.json").is_file():
        pytest.skip(f"no shipped prior at {SHIPPED_PRIOR}")
    assert registry.VIDEO_START == "whole"  # the default: a whole head (tests/models/avatars/test_whole.py)
    scratch = ("scratch", None, "from scratch")
    for start in ("prior", "scratch", "whole"):
        monkeypatch.setattr(registry, "VIDEO_START", start)
        way, folder, why = training_start("builtin", True, None, False, None)
        assert way == start and folder == (None if start == "scratch" else SHIPPED_PRIOR), (start, why)
        assert ("personalising" in why) == (start == "prior") and ("whole head" in why) == (start == "whole")
        assert training_start("builtin", False, None, False, None) == scratch
        assert training_start("builtin", True, None, True, None) == ("scratch", None, "from scratch (--from-scratch)")
        assert training_start("builtin", True, "primitives", False, None) == scratch
        way, folder, why = training_start("ict:/x/ict_head.npz", True, None, False, None)  # the built-in head's prior
        assert way == start and ("on the ict head" in why) == (start != "scratch"), why
        assert training_start("builtin", False, None, False, SHIPPED_PRIOR)[:2] == ("prior", SHIPPED_PRIOR)
        assert training_start("builtin", True, "prior", False, None)[:2] == ("prior", SHIPPED_PRIOR)
        assert training_start("builtin", False, "whole", False, None)[:2] == ("whole", SHIPPED_PRIOR)
        for model in ("prior", "whole"):
            with pytest.raises(CheckpointError, match="a primitives avatar, not a universal prior"):
                training_start("builtin", True, model, False, DEMO)
        with pytest.raises(CheckpointError, match="nothing"):  # a prior asked for by name must be one
            training_start("builtin", True, None, False, tmp_path / "nothing")


def test_a_frontal_scans_back_of_the_head_takes_the_hair_colour(tmp_path, gl):
    """A person with long black hair seen only from the front (head turns within 20 degrees): the neutral texture's
    texels no frame saw (the back of the head, the chart's outer columns) are filled from what was seen around
    them, the hair, not with the mean of every seen texel, face included (measured: the back's luminance 0.12 of
    the face's, where the mean fill gave 0.55)."""
    from models.capture.dataset import load_split
    from models.training.prior import neutral_texture

    synthesize(SynthConfig(scene="ambient", frames=12, size=64, identity=5, hair="long", hair_color="black",
                           turn_deg=20, out=tmp_path / "front"), load_builtin(), gl)
    avatar = PriorAvatar(load_builtin(), SMALL, 1, np.full(3, 0.5, np.float32))
    texture = (neutral_texture(load_split(tmp_path / "front", "train"), avatar, gl)[0].permute(1, 2, 0).numpy() + 1) / 2
    S = texture.shape[0]
    lum = texture @ np.array([0.2126, 0.7152, 0.0722])
    middle = slice(S // 3, 2 * S // 3)
    back = np.concatenate([lum[middle, :2], lum[middle, -2:]], 1).mean()
    face = lum[middle, S // 2 - 1:S // 2 + 1].mean()
    assert face > 0.3 and back < 0.3 * face, (back, face)


def test_the_unseen_back_of_the_head_takes_the_crowns_colour_hand_worked():
    """A frontal view of 8 x 8 texels: the middle columns seen, dark hair (0.1) on the crown rows, skin (0.8) below;
    the outer columns unseen. With the texels' heights above the eyes, the unseen ones down to the nape take the
    crown's colour exactly (0.1, where the fill from around gave them 0.57 on average, the skin beside them); below
    the nape they are filled from around as before; the seen ones keep theirs."""
    S = 8
    heights = np.repeat(np.linspace(0.12, -0.12, S)[:, None], S, 1)  # rows top (crown) first
    colour = np.where(heights[..., None] > CROWN_ABOVE_EYES_M, 0.1, 0.8) * np.ones((S, S, 3))
    weight = np.zeros((S, S), np.float32)
    weight[:, 3:5] = 1.0
    plain, seen = average_texture([colour], [weight])
    hair, _ = average_texture([colour], [weight], heights=heights)
    back = ~seen & (heights > -NAPE_BELOW_EYES_M)
    assert back.sum() == 6 * 6 and np.allclose(hair[back], 0.1)
    assert float(plain[back].mean()) > 0.5  # the fill from around: mostly the skin beside (0.57)
    np.testing.assert_array_equal(hair[seen], colour[seen].astype(np.float32))
    nape = ~seen & ~back
    assert np.all((hair[nape] > 0.1) & (hair[nape] < 0.8))  # between the hair above and the neck beside
    # the hair's colour read beyond the mesh (hair_colour), where the frames show it, before the crown's texels
    given, _ = average_texture([colour], [weight], heights=heights, hair=np.array([0.3, 0.2, 0.1]))
    np.testing.assert_allclose(given[back], np.broadcast_to([0.3, 0.2, 0.1], (36, 3)), atol=1e-6)
    np.testing.assert_array_equal(given[seen], colour[seen].astype(np.float32))
    # long hair, seen hanging 10 cm below the eyes: the seventh row (8.6 cm below them) takes it too, the last
    # (12 cm) is filled from around, between the hair above and the neck beside
    long, _ = average_texture([colour], [weight], heights=heights, hair=np.array([0.3, 0.2, 0.1]), hair_reach_m=0.1)
    hangs = ~seen & (heights > -0.1)
    assert hangs.sum() == 7 * 6 and np.allclose(long[hangs], [0.3, 0.2, 0.1])
    below = long[~seen & ~hangs]
    assert np.all((below > np.array([0.3, 0.2, 0.1])) & (below < 0.8))


def test_the_hair_colour_is_the_median_beyond_the_mesh_where_there_is_enough_of_it():
    """hair_colour: the per-channel median of the frames' pixels beyond the mesh, hand-worked; None where they are
    fewer than HAIR_MIN_SHARE of the mesh's pixels above the eyes (a head the mesh fits)."""
    a = np.array([[0.1, 0.2, 0.3], [0.5, 0.5, 0.5]])
    b = np.array([[0.2, 0.1, 0.0]])
    np.testing.assert_allclose(hair_colour([a, b], head_pixels=100), [0.2, 0.2, 0.3])
    assert hair_colour([a, b], head_pixels=int(3 / HAIR_MIN_SHARE) + 1) is None
    assert hair_colour([], head_pixels=0) is None


def test_eye_heights_are_the_templates_heights_above_its_eyes():
    """The built-in head's texels: the crown 11 cm above the eyes (its top, 0.174 m over its middle, the eyes 0.061),
    heights falling from the chart's top row to its bottom, and nan where the chart's ray misses the head."""
    head = load_builtin()
    sampler = chart_sampler(head, 32, 2.0)
    h = eye_heights(head, sampler)
    assert abs(np.nanmax(h) - (0.174 - 0.061)) < 0.01
    rows = np.nanmean(h, 1)
    assert np.all(np.diff(rows[np.isfinite(rows)]) < 0)
    np.testing.assert_array_equal(np.isnan(h).ravel(), ~sampler.valid)


def test_the_prior_sits_on_a_flame_head_as_on_its_own(tmp_path):
    """load_prior on a head model of another kind: a FLAME-format file made from the built-in head (the same mesh and
    bases) gets the shipped prior's weights with its primitives placed on the FLAME head's mesh, and renders what the
    prior renders on the built-in head (an independent reference: the same geometry by another loader)."""
    from models.avatars.registry import SHIPPED_PRIOR, load_avatar, load_prior
    from models.head.flame import load_flame
    from render.camera import orbit_camera
    from tests.models.head.flame_files import write_flame_from_head

    if not (SHIPPED_PRIOR / "avatar.json").is_file():
        pytest.skip(f"no shipped prior at {SHIPPED_PRIOR}")
    path = write_flame_from_head(tmp_path / "flame", load_builtin())
    spec = f"flame:{path}"
    on_flame, meta = load_prior(SHIPPED_PRIOR, spec)
    own, _ = load_avatar(SHIPPED_PRIOR)
    assert meta["head_model"] == spec and on_flame.head_model.name != own.head_model.name
    assert on_flame.head_model.name == load_flame(path).name
    assert torch.equal(on_flame.layout_triangles, own.layout_triangles)  # the same mesh: the same places
    controls = Controls(expression=np.eye(own.head_model.num_expression, dtype=np.float32)[0] * 0.8)
    cam = orbit_camera(40.0, 5.0, 0.6, width_px=48, height_px=48)
    a = render_image(on_flame, cam, controls)["rgb"]
    b = render_image(own, cam, controls)["rgb"]
    assert float(np.abs(b - b.mean((0, 1))).mean()) > 0.02  # a head, not a blank
    np.testing.assert_allclose(a, b, atol=2e-3)
