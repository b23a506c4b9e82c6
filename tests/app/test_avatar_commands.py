"""`train`, `eval`, `render` as a user runs them: a tiny end-to-end run, and bad input answered with exit
status 2 and one line naming the file."""

from __future__ import annotations

import contextlib
import io
import json
import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from app.cli import main

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def capture(synth_capture) -> Path:
    return synth_capture("studio", 12, 24)


def test_train_eval_render(capture, tmp_path, capsys):
    avatar = tmp_path / "av"
    assert main(["train", str(capture), "--out", str(avatar), "--effects", "shading", "--steps", "6",
                 "--rays-per-step", "128"]) == 0
    n = len(json.loads((capture / "transforms_train.json").read_text())["frames"])
    assert f"reading the frames: {n}/{n} frames" in capsys.readouterr().err  # a long video's reading is shown
    lines = (avatar / "progress.jsonl").read_text().splitlines()
    assert json.loads(lines[0])["step"] == 1 and "eta_s" in json.loads(lines[-1])
    assert all(json.loads(line)["eta_s"] >= 0 for line in lines)  # the last step: 0 s left, not -1
    # Resuming with a larger budget continues from step 6.
    assert main(["train", str(capture), "--out", str(avatar), "--effects", "shading", "--steps", "8",
                 "--rays-per-step", "128", "--resume"]) == 0
    assert json.loads((avatar / "avatar.json").read_text())["step"] == 8
    capsys.readouterr()
    assert main(["train", str(capture), "--out", str(avatar), "--effects", "none", "--steps", "9", "--resume"]) == 2
    assert "trained with shading" in capsys.readouterr().err  # not silently ignored
    assert main(["eval", str(avatar), str(capture), "--out", str(tmp_path / "ev")]) == 0
    metrics = json.loads((tmp_path / "ev" / "metrics.json").read_text())["metrics"]
    assert {"psnr", "ssim", "face_mse", "offset_px", "normal_deg", "render_ms"} <= set(metrics)
    side = np.asarray(Image.open(tmp_path / "ev" / "test_0000.png"))
    assert side.shape == (24, 24 * 4, 3)  # ground truth, render, error, normals
    for buffer in ("rgb", "normals", "depth", "opacity"):
        out = tmp_path / f"{buffer}.png"
        assert main(["render", str(avatar), "--buffer", buffer, "--size", "32", "--out", str(out)]) == 0
        assert np.asarray(Image.open(out)).shape == (32, 32, 3)


def test_bad_input(capture, tmp_path, capsys):
    assert main(["train", str(tmp_path / "missing"), "--out", str(tmp_path / "a")]) == 2
    assert "no such dataset folder" in capsys.readouterr().err
    assert main(["render", str(tmp_path), "--out", str(tmp_path / "x.png")]) == 2
    assert "not an avatar folder" in capsys.readouterr().err
    assert main(["train", str(capture), "--out", str(tmp_path / "b"), "--effects", "glitter"]) == 2
    assert "unknown effect" in capsys.readouterr().err
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "avatar.json").write_text("{}")
    assert main(["train", str(capture), "--out", str(tmp_path / "c"), "--steps", "1"]) == 2
    assert "already holds an avatar" in capsys.readouterr().err
    assert (tmp_path / "c" / "avatar.json").read_text() == "{}"
    for options, why in ((["grid=1000"], "--model-options grid=1000: must be at least 8 and at most 256"),
                         (["glow=1"], "--model-options glow=1: not a setting of this model (its settings: grid,"),
                         (["expression_maps=maybe"], "expression_maps must be true or false")):
        assert main(["train", str(capture), "--out", str(tmp_path / "d"), "--model", "primitives", "--steps", "1",
                     "--model-options", *options]) == 2
        assert why in capsys.readouterr().err
        assert not (tmp_path / "d" / "avatar.json").exists()
    # every model takes its own config's fields (CoDyNeRF's loss weights), and the avatar records what it was given
    assert main(["train", str(capture), "--out", str(tmp_path / "e"), "--steps", "1", "--rays-per-step", "64",
                 "--model-options", "cauchy=0.5"]) == 0
    meta = json.loads((tmp_path / "e" / "avatar.json").read_text())
    assert meta["provenance"]["config"]["model_options"] == "('cauchy=0.5',)"
    assert main(["train", str(capture), "--out", str(tmp_path / "f"), "--steps", "1", "--model", "nerface",
                 "--model-options", "cauchy=0.5"]) == 2
    assert "--model-options cauchy=0.5: not a setting of this model" in capsys.readouterr().err


@pytest.mark.skipif(__import__("torch").cuda.is_available(), reason="this machine has a CUDA GPU")
def test_cuda_without_a_gpu_is_a_clear_error(capture, tmp_path, capsys):
    assert main(["train", str(capture), "--out", str(tmp_path / "a"), "--device", "cuda", "--steps", "1"]) == 2
    assert "torch sees no CUDA GPU" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()


def test_shadow_buffers_and_metrics(synth_capture, tmp_path, capsys):
    """An `all` avatar on a sun capture (which has the cast-shadow masks and the frames without cast shadows):
    eval reports the shadow figures and adds the without-shadows and shadows panels; render writes the shadow
    buffers; an avatar without shadows refuses them with exit 2 naming the avatar."""
    capture = synth_capture("sun", 12, 24)
    avatar = tmp_path / "all"
    assert main(["train", str(capture), "--out", str(avatar), "--effects", "all", "--steps", "6",
                 "--rays-per-step", "128"]) == 0
    assert main(["eval", str(avatar), str(capture), "--out", str(tmp_path / "ev")]) == 0
    report = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    m = report["metrics"]
    assert {"shadow_corr", "unshadowed_psnr", "unshadowed_psnr_render"} <= set(m)
    assert -1 <= m["shadow_corr"] <= 1 and all(np.isfinite(m[k]) for k in m)
    side = np.asarray(Image.open(tmp_path / "ev" / "test_0000.png"))
    assert side.shape == (24, 24 * 6, 3)  # ground truth, render, error, normals, without shadows, shadows x4
    for buffer in ("rgb_no_shadows", "rgb_light", "shadow_change", "shading"):
        out = tmp_path / f"{buffer}.png"
        assert main(["render", str(avatar), "--buffer", buffer, "--size", "32", "--out", str(out)]) == 0
        img = np.asarray(Image.open(out))
        assert img.shape == (32, 32, 3)
        if buffer == "rgb_light":  # off the head all the light arrives: white corners
            assert (img[0, 0] == 255).all() and (img[-1, -1] == 255).all()
    shading = tmp_path / "shading_only"
    assert main(["train", str(capture), "--out", str(shading), "--effects", "shading", "--steps", "1",
                 "--rays-per-step", "64"]) == 0
    capsys.readouterr()
    assert main(["render", str(shading), "--buffer", "rgb_light", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "rgb_light" in err and str(shading) in err and "shading" in err
    assert not (tmp_path / "x.png").exists()


def test_turntable_sweeps_about_the_front(tmp_path, capsys, gl):
    """--sweep-deg 30: the camera swings to 30 degrees each side and back (frames 0 and 2 of 4 are the front view,
    1 and 3 the two sides, mirror images of each other's yaw), instead of circling the head."""
    from app.turntable import TurntableConfig, turntable_frames
    from models.avatars.registry import load_avatar
    from render.gl.raster import Rasterizer

    demo = Path(__file__).resolve().parents[2] / "resources" / "demo_avatar"
    avatar, _ = load_avatar(demo)
    cfg = TurntableConfig(avatar=demo, frames=4, sweep_deg=30.0, size=32, preset="draft")
    frames = list(turntable_frames(avatar, Rasterizer(gl), cfg))
    full = list(turntable_frames(avatar, Rasterizer(gl), TurntableConfig(avatar=demo, frames=12, size=32,
                                                                         sweep_deg=0.0, preset="draft")))
    assert np.abs(frames[0].astype(int) - frames[2]).max() <= 1  # sin(pi) = 1e-16: the front again
    np.testing.assert_array_equal(frames[0], full[0])  # yaw 0 in both
    np.testing.assert_array_equal(frames[1], full[1])  # 30 degrees: the full turn's second of 12 frames
    assert np.abs(frames[1].astype(int) - frames[3]).mean() > 1  # the other side
    assert main(["turntable", str(demo), "--sweep-deg", "200", "--out", str(tmp_path / "t.mp4")]) == 2
    assert "--sweep-deg 200" in capsys.readouterr().err


def test_ctrl_c_checkpoints_and_a_second_writer_is_refused(capture, tmp_path, capsys):
    """A trainer holds its avatar folder: a second `train` into it ends at once with exit 2 naming the holder.
    Ctrl-C (SIGINT) checkpoints and exits 0, like the studio's Cancel; resuming then logs no step twice."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "av"
    repo = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "train", str(capture), "--out", str(out), "--effects",
                             "none", "--steps", "100000", "--rays-per-step", "64", "--checkpoint-seconds", "1e9"],
                            cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 300
        while not (out / "progress.jsonl").exists() or len((out / "progress.jsonl").read_text().splitlines()) < 2:
            assert proc.poll() is None and time.monotonic() < deadline, proc.stdout.read() if proc.poll() else ""
            time.sleep(0.2)
        assert main(["train", str(capture), "--out", str(out), "--effects", "none", "--steps", "5", "--resume"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"in use by avatar-studio train (pid {proc.pid})" in err[0], err
        proc.send_signal(signal.SIGINT)
        stdout, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and "stopped at step" in stdout, stdout
    step = json.loads((out / "avatar.json").read_text())["step"]
    assert step > 50
    with open(out / "progress.jsonl", "a") as f:  # a record past the checkpoint, as a kill can leave
        f.write(json.dumps({"step": step + 3, "loss": 1.0}) + "\n")
    assert main(["train", str(capture), "--out", str(out), "--effects", "none", "--steps", str(step + 60),
                 "--rays-per-step", "64", "--resume"]) == 0
    steps = [json.loads(line)["step"] for line in (out / "progress.jsonl").read_text().splitlines()]
    assert steps == sorted(set(steps)) and steps[-1] == step + 60


def test_demo_avatar_normals_are_its_surface(gl, tmp_path):
    """The shipped demo (volumetric primitives, sun scene) against a fresh capture of its person (the demo head, the
    look of its identity seed) under its scene with true normals: the normals buffer is a surface's (the guide
    mesh's where the render lies on it, the depth's elsewhere), median error over the face's drawn pixels at most 15
    degrees (41 degrees mean, voxel gradients, before), and mean at most 20."""
    from models.capture.synthetic import SynthConfig, synthesize
    from models.head.sources import DEMO_HEAD_PATH, load_head

    seed = int(np.load(DEMO_HEAD_PATH)["identity_seed"])
    capture = tmp_path / "capture"
    synthesize(SynthConfig(head="demo", identity=seed, scene="sun", frames=20, size=96, out=capture),
               load_head("demo"), gl)
    assert main(["eval", "resources/demo_avatar", str(capture), "--out", str(tmp_path / "ev")]) == 0
    report = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    m = report["metrics"]
    assert report["frames"] >= 2
    assert m["normal_median_deg"] <= 15.0 and m["normal_deg"] <= 20.0, m
    assert m["psnr"] > 20.0  # it is the head of the capture, in its place


@pytest.fixture(scope="module")
def tiny_avatar(capture, tmp_path_factory) -> tuple[Path, str, str]:
    """An avatar of `capture` after 3 steps, a progress record each (PROGRESS_SECONDS 0: as a capture's slow steps
    get one every 5 s), and what `train` printed (stdout, stderr)."""
    import app.avatar_commands
    import models.training.trainer

    out = tmp_path_factory.mktemp("tiny") / "avatar"
    with pytest.MonkeyPatch.context() as mp:
        for module in (app.avatar_commands, models.training.trainer):
            mp.setattr(module, "PROGRESS_SECONDS", 0.0)
        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            assert main(["train", str(capture), "--out", str(out), "--effects", "none", "--steps", "3",
                         "--rays-per-step", "64"]) == 0
    return out, stdout.getvalue(), stderr.getvalue()


def test_train_shows_the_photometric_error_and_what_next(tiny_avatar, capture):
    """A record (and in a log, a line) at every step here: time-based, not only every 50 steps; each line has the
    photometric error apart from the weighted total. The last line says what to run next. The folder holds no
    lock, and the weights have the user's permissions (they were 0600)."""
    avatar, out, err = tiny_avatar
    records = [json.loads(line) for line in (avatar / "progress.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == [1, 2, 3]
    lines = [line for line in err.splitlines() if line.startswith("step ")]
    assert len(lines) == 3
    for line, r in zip(lines, records, strict=True):
        assert f"photometric {r['photometric']:.5f}  total {r['loss']:.5f}" in line, (line, r)
    assert r["loss"] != r["photometric"]  # the total weighs in other terms
    assert out.splitlines()[-1] == (f"next: avatar-studio studio {avatar}  (or: avatar-studio turntable {avatar}; "
                                    f"avatar-studio eval {avatar} {capture})")
    assert ".writer.lock" not in [p.name for p in avatar.iterdir()]
    umask = os.umask(0o022)
    os.umask(umask)
    assert {oct(p.stat().st_mode & 0o777) for p in avatar.glob("*.safetensors")} == {oct(0o666 & ~umask)}


def test_an_avatar_and_a_capture_given_for_each_other_are_named(tiny_avatar, capture, tmp_path, capsys):
    """An avatar where a capture belongs, and a capture where an avatar belongs: exit 2 and one line saying which
    is which (they said 'transforms_train.json: no such file' and 'not an avatar folder'). The failed train leaves
    no folder behind (it left one holding only .writer.lock)."""
    avatar = tiny_avatar[0]
    is_avatar = (f"{avatar}: is an avatar (it holds avatar.json), not a capture dataset; it was trained on the "
                 f"capture {capture}")
    for argv in (["train", str(avatar), "--out", str(tmp_path / "made" / "av")],
                 ["eval", str(avatar), str(avatar), "--out", str(tmp_path / "ev")], ["dataset", str(avatar)]):
        assert main(argv) == 2
        assert capsys.readouterr().err.splitlines() == [f"avatar-studio {argv[0]}: error: {is_avatar}"]
    assert not (tmp_path / "made").exists()
    is_capture = f"{capture}: is a capture dataset, not an avatar (train one with: avatar-studio train {capture})"
    for argv in (["render", str(capture), "--out", str(tmp_path / "x.png")],
                 ["eval", str(capture), str(capture), "--out", str(tmp_path / "ev")],
                 ["turntable", str(capture), "--out", str(tmp_path / "t.mp4")]):
        assert main(argv) == 2
        assert capsys.readouterr().err.splitlines() == [f"avatar-studio {argv[0]}: error: {is_capture}"]
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_eval_says_where_it_wrote_and_warns_of_another_head(tiny_avatar, capture, tmp_path, capsys):
    """eval's last line names metrics.json, the images and the PSNR in it (synth's, what to run next). Against a
    capture of another person (synth --identity 3: its shape moves the built-in head 22 mm) or tracked with another
    head model, one warning line, and the eval still runs."""
    import shutil

    avatar = tiny_avatar[0]
    assert main(["eval", str(avatar), str(capture), "--out", str(tmp_path / "ev")]) == 0
    out, err = capsys.readouterr()
    psnr = json.loads((tmp_path / "ev" / "metrics.json").read_text())["metrics"]["psnr"]
    assert out.splitlines()[-1].startswith(f"wrote {tmp_path / 'ev' / 'metrics.json'} and 1 side-by-side image (")
    rendering = [line for line in err.splitlines() if line.startswith("rendering the test frames: ")]  # progress
    assert f"; PSNR {psnr:.2f} dB, SSIM" in out.splitlines()[-1] and err.splitlines() == rendering
    assert rendering[-1].startswith("rendering the test frames: 1/1 frames (")
    other = tmp_path / "other"
    assert main(["synth", "--identity", "3", "--frames", "10", "--size", "24", "--out", str(other)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"next: avatar-studio train {other} --out {other}_avatar"
    flame = tmp_path / "flame_tracked"
    shutil.copytree(capture, flame)
    test = json.loads((flame / "transforms_test.json").read_text())
    (flame / "transforms_test.json").write_text(json.dumps({**test, "head_model": "flame:/elsewhere/flame.npz"}))
    for dataset, why in ((other, "of another person than the avatar's (their identity shapes move the head up to 22 "
                                 "mm apart)"),
                         (flame, "tracked with the head model flame:/elsewhere/flame.npz, the avatar with builtin")):
        assert main(["eval", str(avatar), str(dataset), "--out", str(tmp_path / f"ev_{dataset.name}")]) == 0
        err = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("rendering the ")]
        assert len(err) == 1 and err[0].startswith(f"avatar-studio eval: warning: {dataset}: {why}"), err
        assert (tmp_path / f"ev_{dataset.name}" / "metrics.json").is_file()
