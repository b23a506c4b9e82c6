"""Checkpoints: bit-exact round trip, and a crash at any point of a save leaves the previous one whole."""

from __future__ import annotations

import json
import os

import pytest
import torch

from models.avatars.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from tests.conftest import CODYNERF_DEMO, DEMO


def tensors(seed: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return {"mlp.0.weight": torch.randn(64, 32, generator=g), "mlp.0.bias": torch.randn(64, generator=g).double(),
            "codes": torch.randn(10, 8, generator=g).to(torch.bfloat16), "step_counts": torch.arange(5),
            "rng": torch.Generator().manual_seed(seed).get_state()}


def test_round_trip_bit_exact(tmp_path):
    w, s = tensors(0), tensors(1)
    save_checkpoint(tmp_path / "a", {"effects": ["shading"], "head_model": "builtin"}, w, step=120, train_state=s)
    ck = load_checkpoint(tmp_path / "a", with_train_state=True)
    assert ck.step == 120 and ck.meta["effects"] == ["shading"]
    for ref, got in ((w, ck.weights), (s, ck.train_state)):
        assert ref.keys() == got.keys()
        for k in ref:
            assert got[k].dtype == ref[k].dtype and torch.equal(got[k], ref[k]), k


def test_old_files_removed_after_a_new_save(tmp_path):
    save_checkpoint(tmp_path, {}, tensors(0), step=1, train_state=tensors(1))
    save_checkpoint(tmp_path, {}, tensors(2), step=2, train_state=tensors(3))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["avatar.json", "train_state-000002.safetensors",
                                                          "weights-000002.safetensors"]


@pytest.mark.parametrize("crash_at", [1, 2, 3])
def test_crash_during_save_keeps_the_previous_checkpoint(tmp_path, monkeypatch, crash_at):
    """The save is killed at its 1st, 2nd or 3rd rename (weights, train state, json)."""
    save_checkpoint(tmp_path, {"note": "old"}, tensors(0), step=10, train_state=tensors(1))
    real_replace, calls = os.replace, []

    def dying_replace(src, dst):
        calls.append(dst)
        if len(calls) == crash_at:
            raise KeyboardInterrupt("killed")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", dying_replace)
    with pytest.raises(KeyboardInterrupt):
        save_checkpoint(tmp_path, {"note": "new"}, tensors(5), step=11, train_state=tensors(6))
    monkeypatch.setattr(os, "replace", real_replace)
    ck = load_checkpoint(tmp_path, with_train_state=True)
    assert ck.step == 10 and ck.meta["note"] == "old"
    assert torch.equal(ck.weights["mlp.0.weight"], tensors(0)["mlp.0.weight"])
    assert not list(tmp_path.glob("*.tmp"))  # no half-written files left behind


def test_bad_folders_name_the_problem(tmp_path):
    with pytest.raises(CheckpointError, match="not an avatar folder"):
        load_checkpoint(tmp_path)
    save_checkpoint(tmp_path, {}, tensors(0), step=3)
    meta = json.loads((tmp_path / "avatar.json").read_text())
    meta["files"]["weights"] = "../../etc/passwd"
    (tmp_path / "avatar.json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match=r"files\.weights' must name a file beside it"):
        load_checkpoint(tmp_path)
    meta["files"]["weights"] = "weights-000003.safetensors"
    (tmp_path / "avatar.json").write_text(json.dumps(meta))
    (tmp_path / "weights-000003.safetensors").write_bytes(b"\x00" * 20)
    with pytest.raises(CheckpointError, match="not a readable safetensors file"):
        load_checkpoint(tmp_path)


@pytest.mark.parametrize(("demo", "change"), [
    (CODYNERF_DEMO, c) for c in [
        {"background": "abc"}, {"background": [0.5, 0.5]}, {"frames": "many"}, {"frames": 0}, {"frames": 7},
        {"render": {"chunk_rays": 0}}, {"render": {"samples_per_ray": 0}}, {"render": {"shell_m": -0.03}},
        {"field": {"light_dir": [0, 0, 0]}}, {"field": {"width": 65}}]] + [
    (DEMO, c) for c in [
        {"frames": 7}, {"primitives": {"grid": 0}}, {"primitives": {"samples": "many"}},
        {"primitives": {"width": 65}}, {"light_dir": [0, 0, 0]}, {"primitives": {"voxels": 1}}]])
def test_a_broken_avatar_json_is_one_clear_line(demo, change, tmp_path, capsys):
    """Each of these once ended in a traceback, a torch dump or a silent wrong render."""
    import shutil

    from app.cli import main

    folder = tmp_path / "av"
    shutil.copytree(demo, folder)
    meta = json.loads((folder / "avatar.json").read_text())
    for key, value in change.items():
        meta[key] = {**meta[key], **value} if isinstance(value, dict) else value
    (folder / "avatar.json").write_text(json.dumps(meta))
    assert main(["render", str(folder), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "avatar.json" in err[0], err
    assert not (tmp_path / "x.png").exists()


def test_leftovers_of_killed_writes_are_cleaned_and_nothing_else(tmp_path):
    folder = tmp_path / "av"
    folder.mkdir()
    left = [folder / ".weights-000003.safetensors.ab12cd.tmp", folder / ".avatar.json.x9y8.tmp"]
    mine = [folder / "notes.tmp", folder / ".my.tmp", folder / "weights-000001.safetensors.bak"]
    for p in left + mine:
        p.write_bytes(b"x")
    save_checkpoint(folder, {"model": "codynerf"}, {"w": torch.zeros(2)}, 5)
    assert not any(p.exists() for p in left)
    assert all(p.exists() for p in mine)  # not the program's names: not touched


def test_a_tool_for_one_model_is_refused_another_models_avatar():
    """load_avatar(model=...): a model's own benchmark or picture gets that model's avatar, or one clear line naming
    the model the folder holds (before any weights are read)."""
    from models.avatars.registry import load_avatar

    avatar, meta = load_avatar(DEMO, model="primitives")
    assert avatar.name == meta["model"] == "primitives"
    with pytest.raises(CheckpointError, match=r"codynerf_avatar: a codynerf avatar, not a primitives one"):
        load_avatar(CODYNERF_DEMO, model="primitives")
