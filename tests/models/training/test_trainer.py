"""A training step (models/training/trainer.py): Adam's step taken on a finite loss exactly as a plain backward,
clip and step take it; a step whose loss or gradient is not finite skipped, the weights and Adam's moments as
they were; a target colour that is no number left out of the step."""

from __future__ import annotations

import copy
import math

import pytest
import torch

from models.training.trainer import TrainConfig, finite_terms, optimiser_step, prepare_training


def tiny() -> tuple[torch.nn.Module, torch.optim.Adam]:
    torch.manual_seed(0)
    model = torch.nn.Linear(3, 2)
    return model, torch.optim.Adam(model.parameters(), lr=0.1)


def loss_of(model: torch.nn.Module, poison: str | None = None) -> torch.Tensor:
    x = torch.tensor([[1.0, -2.0, 0.5], [0.0, 3.0, -1.0]])
    loss = (model(x) ** 2).mean()
    if poison == "NaN term":
        loss = loss + float("nan") * model.bias.sum()
    elif poison == "inf gradient":  # d sqrt(|w|) / dw at w = 0 is infinite; the loss, 0, is finite
        loss = loss + torch.sqrt(model.weight[0, 0] * 0.0).sum()
    return loss


def test_a_finite_step_is_a_plain_clipped_adam_step_bit_for_bit():
    """Two steps through optimiser_step and two of backward, clip_grad_norm_ (to 0.5: the first gradient's norm,
    about 6, is clipped) and Adam: the same weights and moments, bit for bit."""
    model, opt = tiny()
    plain = copy.deepcopy(model)
    plain_opt = torch.optim.Adam(plain.parameters(), lr=0.1)
    for _ in range(2):
        terms, stepped = optimiser_step(opt, model, loss_of(model), {}, 0.5)
        assert stepped and math.isfinite(terms["loss"])
        plain_opt.zero_grad(set_to_none=True)
        loss_of(plain).backward()
        torch.nn.utils.clip_grad_norm_(plain.parameters(), 0.5)
        plain_opt.step()
    for a, b in zip(model.parameters(), plain.parameters(), strict=True):
        assert torch.equal(a, b)
    for p, q in zip(model.parameters(), plain.parameters(), strict=True):
        for key in ("exp_avg", "exp_avg_sq", "step"):
            assert torch.equal(opt.state[p][key], plain_opt.state[q][key]), key


@pytest.mark.parametrize("poison", ["NaN term", "inf gradient"])
def test_a_step_with_a_nan_loss_or_an_infinite_gradient_is_skipped(poison):
    """One finite step, then a poisoned one: skipped, the weights and Adam's moments and step count those of the
    first step bit for bit, no gradient left behind; the next finite step takes Adam's second step."""
    model, opt = tiny()
    optimiser_step(opt, model, loss_of(model), {}, 1.0)
    weights = [p.detach().clone() for p in model.parameters()]
    moments = copy.deepcopy(opt.state_dict()["state"])
    terms, stepped = optimiser_step(opt, model, loss_of(model, poison), {"photometric": torch.tensor(0.25)}, 1.0)
    assert not stepped
    assert terms["photometric"] == 0.25
    assert not math.isfinite(terms["loss"]) or poison == "inf gradient"
    for p, w in zip(model.parameters(), weights, strict=True):
        assert torch.equal(p.detach(), w) and p.grad is None
    for k, st in opt.state_dict()["state"].items():
        for key, v in st.items():
            assert torch.equal(v, moments[k][key]), key
    _, stepped = optimiser_step(opt, model, loss_of(model), {}, 1.0)
    assert stepped and float(opt.state[model.bias]["step"]) == 2.0


def test_finite_terms_leave_out_what_json_cannot_hold():
    # round(0.1234567, 6) = 0.123457; NaN and -inf left out.
    assert finite_terms({"a": 0.1234567, "b": float("nan"), "c": -float("inf"), "loss": 2.0}) == {"a": 0.123457,
                                                                                                 "loss": 2.0}


@pytest.mark.gl
def test_a_target_colour_that_is_no_number_is_left_out_of_the_step(synth_capture, gl, tmp_path, monkeypatch):
    """One ray of each frame with a NaN target colour, another with an infinite one (as a ray that misses the head
    could have): those rays are left out, the step is taken on the rest (none skipped) and its logged terms and
    the weights are finite."""
    capture = synth_capture("ambient", 12, 24)
    t = prepare_training(TrainConfig(dataset=capture, out=tmp_path / "av", steps=2, rays_per_step=64,
                                     effects="none"), gl)
    before = {k: v.detach().clone() for k, v in t.avatar.state_dict().items() if v.is_floating_point()}
    target, seen = t.frames.target, []

    def holes(fid, pick):
        x = target(fid, pick).clone()
        x[0, 1], x[-1, 2] = float("nan"), float("inf")
        return x

    def counting(batch):
        seen.append(len(batch.target))
        return loss_terms(batch)

    loss_terms = t.avatar.loss_terms
    monkeypatch.setattr(t.frames, "target", holes)
    monkeypatch.setattr(t.avatar, "loss_terms", counting)
    terms = t.train_step(0.0)
    assert t.skipped_steps == 0
    assert seen and all(n == 64 // t.frames_per_step - 2 for n in seen), seen
    assert all(math.isfinite(v) for v in terms.values()), terms
    after = {k: v for k, v in t.avatar.state_dict().items() if k in before}
    assert all(torch.isfinite(v).all() for v in after.values())
    assert any(not torch.equal(after[k], before[k]) for k in before)  # it trained


@pytest.mark.parametrize(("model", "given", "frames"), [("primitives", None, 2), ("codynerf", None, 4),
                                                         ("primitives", 3, 3)])
def test_a_step_draws_the_models_frames_unless_told(synth_capture, gl, tmp_path, monkeypatch, model, given, frames):
    """A step of the volumetric primitives draws 2 frames (each decoded apart: a step of 4 cost 1.65 times one of
    2), the other models 4, `--frames-per-step` any number; the step's rays are shared evenly between them, and
    the avatar's provenance records the number."""
    capture = synth_capture("ambient", 12, 24)
    t = prepare_training(TrainConfig(dataset=capture, out=tmp_path / "av", steps=1, rays_per_step=60, model=model,
                                     effects="none", frames_per_step=given), gl)
    seen = []
    loss_terms = t.avatar.loss_terms
    monkeypatch.setattr(t.avatar, "loss_terms", lambda batch: seen.append(len(batch.target)) or loss_terms(batch))
    t.train_step(0.0)
    assert seen == [60 // frames] * frames
    assert t.meta()["provenance"]["frames_per_step"] == frames
