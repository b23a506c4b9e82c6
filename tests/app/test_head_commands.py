"""`avatar-studio preview`, `mesh` and `studio` as a user runs them: files written, pixels and vertices
checked, and bad input answered with exit status 2 and one line naming the file."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from PIL import Image

from app.cli import main
from models.head.controls import load_controls
from models.head.head import Head, posed_mesh
from tests.models.head.flame_files import CommandRunningObject, flame_arrays, write_flame_2023

CLI = [sys.executable, "-m", "app.cli"]


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=300,
                          cwd=Path(__file__).resolve().parents[2], env={**os.environ})


@pytest.mark.gl
def test_preview_writes_the_head(tmp_path):
    out = tmp_path / "neutral.png"
    assert main(["preview", "--size", "96", "80", "--out", str(out)]) == 0
    img = np.asarray(Image.open(out))
    assert img.shape == (80, 96, 3)
    background = np.array([0.16, 0.17, 0.19]) * 255
    head = np.abs(img.astype(float) - background).sum(2) > 10
    assert 0.15 < head.mean() < 0.8  # a head in the middle, background around it
    assert not head[:, :3].any() and not head[:, -3:].any()


@pytest.mark.gl
def test_jaw_open_changes_the_mouth(tmp_path):
    controls = tmp_path / "jaw.json"
    controls.write_text(json.dumps({"pose": {"jaw": [0.3, 0.0, 0.0]}}))
    main(["preview", "--size", "128", "128", "--out", str(tmp_path / "a.png")])
    main(["preview", "--size", "128", "128", "--controls", str(controls), "--out", str(tmp_path / "b.png")])
    a = np.asarray(Image.open(tmp_path / "a.png")).astype(int)
    b = np.asarray(Image.open(tmp_path / "b.png")).astype(int)
    changed = np.abs(a - b).sum(2) > 30
    rows = np.nonzero(changed.any(1))[0]
    assert changed.sum() > 40
    # The change is in the lower half of the face, not at the eyes or above.
    assert rows.min() > 128 * 0.45


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_mesh_keeps_vertex_order(tmp_path, builtin_model, suffix):
    controls = tmp_path / "c.json"
    controls.write_text(json.dumps({"expression": {"smile_L": 0.8}, "pose": {"root": [0.1, 0.5, 0.0],
                                                                              "jaw": [0.2, 0, 0]},
                                    "gaze": {"left": [0, 0.2, 0]}, "translation": [0.01, 0, 0]}))
    out = tmp_path / f"head{suffix}"
    assert main(["mesh", "--controls", str(controls), "--out", str(out)]) == 0
    loaded = trimesh.load(out, process=False, maintain_order=True)
    expected, _ = posed_mesh(Head(builtin_model), load_controls(controls, builtin_model))
    np.testing.assert_allclose(loaded.vertices, expected, atol=1e-6)
    np.testing.assert_array_equal(loaded.faces, builtin_model.triangles)


@pytest.mark.gl
def test_flame_head_through_the_cli(tmp_path):
    path = write_flame_2023(tmp_path / "flame", flame_arrays())
    out = tmp_path / "f.obj"
    assert main(["mesh", "--head", f"flame:{path}", "--expression", "3=1.5", "--out", str(out)]) == 0
    assert len(trimesh.load(out, process=False).vertices) == 600


def _bad_inputs(tmp: Path, ict_dir: Path | None) -> dict[str, tuple[list[str], str]]:
    truncated = tmp / "truncated.npz"
    np.savez(truncated, neutral_m=np.zeros((10, 3)))
    truncated.write_bytes(truncated.read_bytes()[:100])
    flame_dir = tmp / "flame_bad"
    arrays = flame_arrays()
    arrays["shapedirs"] = arrays["shapedirs"][:, :, :40]
    bad_flame = write_flame_2023(flame_dir, arrays)
    no_neutral = tmp / "FaceXModel"
    no_neutral.mkdir()
    (no_neutral / "jawOpen.obj").write_text("v 0 0 0\n")
    bad_json = tmp / "bad.json"
    bad_json.write_text('{"pose": {"jaw": [0.1, 0.2]}')
    wrong_json = tmp / "wrong.json"
    wrong_json.write_text('{"pose": {"jaw": [0.1, 0.2]}}')
    return {
        "missing file": (["--head", f"ict:{tmp / 'nope.npz'}"], "nope.npz: no such file"),
        "truncated npz": (["--head", f"ict:{truncated}"], "truncated.npz: not a readable npz"),
        "flame wrong shapes": (["--head", f"flame:{bad_flame}"], "FLAME field 'shapedirs' must be"),
        "obj folder without neutral": (["--head", f"ict:{no_neutral}"], "generic_neutral_mesh.obj is missing"),
        "malformed controls json": (["--controls", str(bad_json)], "bad.json: not valid JSON"),
        "controls of the wrong shape": (["--controls", str(wrong_json)], "wrong.json: pose.jaw must be 3 numbers"),
        "unknown head kind": (["--head", "smpl:x.pkl"], "expected builtin, demo, ict:PATH or flame:PATH"),
    }


CASES = ["missing file", "truncated npz", "flame wrong shapes", "obj folder without neutral",
         "malformed controls json", "controls of the wrong shape", "unknown head kind"]


@pytest.mark.parametrize("case", CASES)
def test_bad_input_exit_2_one_line(tmp_path, case, capsys):
    """Run in this process through the command line's own main (the exit status a process gets is its return
    value: test_malicious_pickle_refused_with_exit_2_and_nothing_runs runs one as a process)."""
    args, message = _bad_inputs(tmp_path, None)[case]
    out = tmp_path / "keep.obj"
    out.write_text("the user's file\n")
    assert main(["mesh", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], err
    assert out.read_text() == "the user's file\n"  # nothing the user had is overwritten


def test_malicious_pickle_refused_with_exit_2_and_nothing_runs(tmp_path):
    marker = tmp_path / "ran"
    evil = tmp_path / "generic_model.pkl"
    evil.write_bytes(pickle.dumps({"f": CommandRunningObject(marker)}))
    r = run_cli("preview", "--head", f"flame:{evil}", "--out", tmp_path / "x.png")
    assert r.returncode == 2
    assert "unsafe pickle" in r.stderr and "generic_model.pkl" in r.stderr
    assert not marker.exists() and not (tmp_path / "x.png").exists()


def test_bad_arguments_exit_2(tmp_path, capsys):
    """A choice argparse refuses ends in its SystemExit(2), a bad value or output name in main's 2; in this
    process."""
    with pytest.raises(SystemExit) as e:
        main(["preview", "--pass", "glitter", "--out", str(tmp_path / "x.png")])
    assert e.value.code == 2 and "invalid choice" in capsys.readouterr().err
    assert main(["preview", "--expression", "smile_L", "--out", str(tmp_path / "x.png")]) == 2
    assert "expected NAME=WEIGHT" in capsys.readouterr().err
    assert main(["mesh", "--out", str(tmp_path / "x.stl")]) == 2
    assert "x.stl: output must end in .obj or .ply" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_ict_through_the_cli(tmp_path, ict_npz, ict_model):
    out = tmp_path / "ict.obj"
    assert main(["mesh", "--head", f"ict:{ict_npz}", "--expression", "jawOpen=1", "--out", str(out)]) == 0
    v = trimesh.load(out, process=False, maintain_order=True).vertices
    expected = Head(ict_model).pose(
        __import__("models.head.controls", fromlist=["Controls"]).Controls().with_expression(ict_model, {"jawOpen": 1})
    )[0][0]
    torch.testing.assert_close(torch.as_tensor(v, dtype=torch.float32), expected, atol=1e-6, rtol=0)


def test_help_comes_from_the_config_docstrings():
    r = run_cli("preview", "--help")
    assert r.returncode == 0
    assert "Camera orbit about the vertical axis, degrees" in r.stdout


def test_every_subcommand_has_a_help_that_formats(capsys):
    """A docstring with a "%" (synth's "about 10%") once broke argparse's help formatting: every command's --help
    exits 0 and shows its options' docstrings."""
    from app.commands import COMMANDS

    for command in COMMANDS:
        with pytest.raises(SystemExit) as e:
            main([command.name, "--help"])
        assert e.value.code == 0, command.name
        capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["synth", "--help"])
    assert "(about 10%)" in " ".join(capsys.readouterr().out.split())  # the docstring's own words, % and all


@pytest.mark.gl
def test_guide_irises_follow_the_gaze(tmp_path):
    """The guide draws each eyeball's iris and pupil about its rest axis: gaze turned 0.4 rad about the vertical
    (towards +x, the image's right from the front) moves both irises' blue pixels right, by pixels read back."""
    gaze = tmp_path / "gaze.json"
    gaze.write_text(json.dumps({"gaze": {"left": [0.0, 0.4, 0.0], "right": [0.0, 0.4, 0.0]}}))
    centres = []
    for extra in ([], ["--controls", str(gaze)]):
        out = tmp_path / f"eyes{len(extra)}.png"
        assert main(["preview", "--size", "256", "256", "--yaw-deg", "0", "--out", str(out), *extra]) == 0
        img = np.asarray(Image.open(out)).astype(int)
        iris = (img[..., 2] > img[..., 0] + 25) & (img[..., 2] > 60)  # blue-grey: skin and background are not
        cols = np.nonzero(iris)[1]
        left, right = cols < 128, cols >= 128
        assert left.sum() > 8 and right.sum() > 8, (left.sum(), right.sum())  # an iris in each eye
        centres.append((cols[left].mean(), cols[right].mean()))
    (l0, r0), (l1, r1) = centres
    assert l1 - l0 > 1 and r1 - r0 > 1 and (l1 - l0) + (r1 - r0) > 4, centres  # a lid covers part of one
