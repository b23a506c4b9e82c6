"""Hard cases for training (models/training/trainer.py, models/avatars/checkpoint.py) on a tiny synthetic capture
(12 frames of 24 px, the default CoDyNeRF avatar, 64 rays a step): targets a million times too bright or below
zero cannot throw the weights further than Adam's step; a NaN batch (a NaN or infinite target colour, a loss term
that is NaN once) must not poison the weights; a run stopped at step 3 and resumed to 5 takes up its checkpoint's
weights bit for bit and ends where a straight 5-step run ends."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.cli import main
from models.avatars.checkpoint import load_checkpoint, save_checkpoint
from models.training.trainer import TrainConfig, Trainer, _adam_state_tensors, prepare_training

pytestmark = pytest.mark.usefixtures("one_torch_thread")
RUN = ["--steps", "5", "--rays-per-step", "64", "--effects", "none"]


@pytest.fixture(scope="module")
def capture(synth_capture) -> Path:
    return synth_capture("ambient", 12, 24)


@pytest.fixture(scope="module")
def trainer(capture, gl, tmp_path_factory, one_torch_thread) -> tuple[Trainer, dict, dict]:
    """A prepared run (reading and rasterizing the frames takes most of its time: done once), with its weights
    and optimiser as they start, for each test to start from."""
    t = prepare_training(TrainConfig(dataset=capture, out=tmp_path_factory.mktemp("avatar") / "av", steps=5,
                                     rays_per_step=64, effects="none"), gl)
    return t, copy.deepcopy(t.avatar.state_dict()), copy.deepcopy(t.opt.state_dict())


def fresh(trainer) -> Trainer:
    t, weights, opt = trainer
    t.avatar.load_state_dict(weights)
    t.opt.load_state_dict(copy.deepcopy(opt))
    t.generator.manual_seed(0)
    t.step = 0
    return t


def floats(state: dict) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in state.items() if torch.is_tensor(v) and v.is_floating_point()}


def adam_moments(opt: torch.optim.Optimizer) -> list[torch.Tensor]:
    return [v for st_ in opt.state.values() for k, v in st_.items() if k in ("exp_avg", "exp_avg_sq")]


@pytest.mark.gl
@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                HealthCheck.function_scoped_fixture])
@given(s=st.sampled_from([0.0, -1.0, 1e3, 1e6, -1e6]))
def test_wild_targets_move_no_weight_further_than_adams_step(trainer, s, monkeypatch):
    """Every target colour times s (black, negative, a million times too bright): the first step's loss and
    gradient may be huge, but the gradient is clipped and Adam's first step is lr * m / (sqrt(v) + eps) with m and
    v from that one gradient, at most lr in size: no weight moves further (lr 5e-3, the first step's schedule)."""
    t = fresh(trainer)
    before = floats(t.avatar.state_dict())
    target = t.frames.target
    monkeypatch.setattr(t.frames, "target", lambda fid, pick: target(fid, pick) * s)
    terms = t.train_step(0.0)
    after = floats(t.avatar.state_dict())
    assert all(torch.isfinite(v).all() for v in after.values())
    assert all(torch.isfinite(torch.tensor(v)) for v in terms.values()), terms
    for group in t.opt.param_groups:
        lr = group["lr"]
        moved = max(float((p.detach() - before[name]).abs().max()) for name, p in t.avatar.named_parameters()
                    if any(p is q for q in group["params"]))
        assert moved <= lr * (1 + 1e-5), (moved, lr)


def poison(t: Trainer, how: str, monkeypatch) -> None:
    """Make the trainer's next step see one bad number."""
    if how in ("NaN target", "inf target"):
        target = t.frames.target
        calls = []

        def bad(fid, pick):
            x = target(fid, pick).clone()
            if not calls:  # the red of the step's first frame (a pixel the avatar draws from its weights among them;
                # one ray that misses the head has a constant colour and no gradient to spoil)
                x[:, 0] = float("nan") if how == "NaN target" else float("inf")
            calls.append(fid)
            return x

        monkeypatch.setattr(t.frames, "target", bad)
    else:  # a loss term that is NaN once (a division by a vanishing weight, say)
        terms = t.avatar.loss_terms
        calls = []

        def nan_once(batch):
            out = terms(batch)
            if not calls:
                key = next(iter(out))
                out = {**out, key: out[key] * float("nan")}
            calls.append(1)
            return out

        monkeypatch.setattr(t.avatar, "loss_terms", nan_once)


@pytest.mark.gl
@pytest.mark.parametrize("how", ["NaN target", "inf target", "NaN loss term"])
def test_a_nan_batch_does_not_poison_the_weights(trainer, how, monkeypatch):
    """After the bad step the weights and Adam's moments are finite (a trainer that skips the step leaves them as
    they were), and the next, clean step trains on."""
    t = fresh(trainer)
    poison(t, how, monkeypatch)
    t.train_step(0.0)
    monkeypatch.undo()
    assert all(torch.isfinite(v).all() for v in floats(t.avatar.state_dict()).values()), "NaN weights"
    assert all(torch.isfinite(m).all() for m in adam_moments(t.opt)), "NaN in Adam's moments"
    terms = t.train_step(0.2)
    assert all(torch.isfinite(torch.tensor(v)) for v in terms.values()), terms


@pytest.mark.gl
def test_a_resumed_run_takes_up_its_checkpoint_and_ends_as_a_straight_run(capture, tmp_path, monkeypatch):
    """`train --steps 5` stopped after step 3 (as Ctrl-C stops it: a checkpoint at step 3), then `train --steps 5
    --resume`: the resumed trainer starts at step 3 with the checkpoint's weights and Adam state bit for bit, and
    ends at step 5 with the weights of a straight `train --steps 5`, bit for bit (the step schedule, the ray
    sampler's generator and Adam's state all come back; CPU, one thread)."""
    stop_at = {"step": 3}
    step = Trainer.train_step

    def stepping(self, progress):
        terms = step(self, progress)
        if self.step == stop_at["step"]:
            self.stop_requested = True
        return terms

    started: dict = {}
    run = Trainer.run

    def running(self, gl, on_progress=None):
        started.setdefault("step", self.step)
        started.setdefault("weights", floats(self.avatar.state_dict()))
        started.setdefault("adam", {k: v.clone() for k, v in _adam_state_tensors(self.opt).items()})
        return run(self, gl, on_progress)

    monkeypatch.setattr(Trainer, "train_step", stepping)
    stopped = tmp_path / "stopped"
    assert main(["train", str(capture), "--out", str(stopped), *RUN]) == 0
    saved = load_checkpoint(stopped, with_train_state=True)
    assert saved.step == 3

    stop_at["step"] = None
    monkeypatch.setattr(Trainer, "run", running)
    assert main(["train", str(capture), "--out", str(stopped), *RUN, "--resume"]) == 0
    assert started["step"] == 3
    saved_weights = floats(saved.weights)
    assert started["weights"].keys() == saved_weights.keys()
    for k, v in saved_weights.items():
        assert torch.equal(started["weights"][k], v), k
    adam = {k: v for k, v in saved.train_state.items() if k.startswith("adam.")}
    assert adam and adam.keys() == started["adam"].keys()
    for k, v in adam.items():
        assert torch.equal(started["adam"][k].cpu(), v), k
    resumed = load_checkpoint(stopped)
    assert resumed.step == 5

    straight = tmp_path / "straight"
    monkeypatch.setattr(Trainer, "run", run)
    assert main(["train", str(capture), "--out", str(straight), *RUN]) == 0
    whole = load_checkpoint(straight)
    assert whole.step == 5
    assert whole.weights.keys() == resumed.weights.keys()
    differ = [k for k in whole.weights if not torch.equal(whole.weights[k], resumed.weights[k])]
    assert not differ, differ
    assert not all(torch.equal(saved.weights[k], whole.weights[k]) for k in saved_weights)  # steps 4, 5 trained


BITS = {torch.float16: torch.int16, torch.bfloat16: torch.int16, torch.float32: torch.int32,
        torch.float64: torch.int64}
special = st.sampled_from([float("nan"), float("inf"), -float("inf"), 0.0, -0.0, 5e-324, 1e-45, 6e-8, 1e-300,
                           3.4e38, 1.7e308, -1.0, 1.0 / 3.0])


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(values=st.lists(special, min_size=0, max_size=12), dtype=st.sampled_from(sorted(BITS, key=str)),
       step=st.sampled_from([0, 1, 999_999, 12_345_678]), transposed=st.booleans(),
       payload=st.integers(1, (1 << 22) - 1))
def test_a_checkpoint_keeps_every_bit_of_extreme_tensors(tmp_path_factory, values, dtype, step, transposed, payload):
    """NaNs (one with a payload in its mantissa), infinities, -0.0, subnormals, numbers that overflow the dtype,
    empty and 0-dim tensors, a transposed (non-contiguous) one, steps past 6 digits: read back bit for bit (compared
    as integers: NaN != NaN to torch.equal)."""
    x = torch.tensor(values, dtype=torch.float64).to(dtype)
    if transposed and len(values) % 2 == 0 and values:
        x = x.reshape(2, -1).t()
    weights = {"x": x, "scalar": torch.tensor(float("nan"), dtype=dtype), "empty": torch.zeros(0, 3, dtype=dtype),
               "payload": torch.tensor([0x7F800000 | payload], dtype=torch.int32).view(torch.float32)}
    folder = tmp_path_factory.mktemp("ck")
    save_checkpoint(folder, {"model": "none"}, weights, step, {"generator": torch.Generator().manual_seed(step)
                                                               .get_state()})
    ck = load_checkpoint(folder, with_train_state=True)
    assert ck.step == step
    for k, v in weights.items():
        got = ck.weights[k]
        assert got.dtype == v.dtype and got.shape == v.shape, k
        bits = BITS[v.dtype]
        assert torch.equal(got.contiguous().view(bits), v.contiguous().view(bits)), k
