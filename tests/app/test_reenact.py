"""`reenact`: the driver's motion relative to their neutral frame, hand-worked; across head models by name; the
command on a real video (the mp4's two halves read back against the video's crop and the avatar's own render of
the animation), its refusals, and its cancel."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from app.reenact import calmest_frame, expression_map, resized, retarget
from models.head.controls import Controls
from tests.app.videos import mp4_frames, psnr
from tests.conftest import DEMO, REPO


def rotvec(yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0, then: np.ndarray | None = None) -> np.ndarray:
    r = Rotation.from_euler("YXZ", [yaw, pitch, roll], degrees=True)
    if then is not None:
        r = r * Rotation.from_rotvec(then)
    return r.as_rotvec().astype(np.float32)


def frames(model, n_expr: int) -> list[Controls]:
    """Three frames: a turned, smiling, open-jawed, glancing one; the neutral one (a slight resting frown, head
    pitched 5 degrees, jaw 0.05 rad); a busier one."""
    rest_expr = np.zeros(n_expr, np.float32)
    rest_expr[model.expression_index("frown_L")] = 0.1
    rest_root = rotvec(pitch=5)
    smile = rest_expr.copy()
    smile[model.expression_index("smile_L")] = 0.5
    busy = np.full(n_expr, 0.6, np.float32)
    return [Controls(expression=smile, root=rotvec(yaw=10, then=rest_root), jaw=np.array([0.25, 0, 0], np.float32),
                     gaze_left=rotvec(yaw=8), gaze_right=rotvec(yaw=8)),
            Controls(expression=rest_expr, root=rest_root, jaw=np.array([0.05, 0, 0], np.float32)),
            Controls(expression=busy, jaw=np.array([0.3, 0, 0], np.float32))]


def test_motion_is_taken_from_the_neutral_frame(builtin_model):
    m = builtin_model
    cs = frames(m, m.num_expression)
    assert calmest_frame(cs) == 1
    anim, how = retarget(cs, [0.0, 0.1, 0.2], m, m, fps=10)
    assert how.neutral == 1 and len(how.carried) == m.num_expression and not how.missing and not how.note
    v = lambda channel, t: anim.value(channel, t)
    assert v("expression.smile_L", 0.0) == pytest.approx(0.5)
    assert v("expression.frown_L", 0.0) == pytest.approx(0.0, abs=1e-6)  # the resting frown is the avatar's rest
    assert v("head.yaw", 0.0) == pytest.approx(10.0, abs=1e-4) and v("head.pitch", 0.0) == pytest.approx(0, abs=1e-4)
    assert v("jaw.open", 0.0) == pytest.approx(math.degrees(0.2), abs=1e-4)
    assert v("gaze.yaw", 0.0) == pytest.approx(8.0, abs=1e-4)
    for channel in anim.tracks:  # the neutral frame drives the avatar to rest
        if not channel.startswith("camera."):
            assert v(channel, 0.1) == pytest.approx(0.0, abs=1e-5), channel
    # the busy frame: head turned back by the neutral frame's pitch; expression kept inside the sliders' range
    assert v("head.pitch", 0.2) == pytest.approx(-5.0, abs=1e-4)
    assert v("expression.frown_L", 0.2) == pytest.approx(0.5)
    assert anim.frames == 3 and anim.interpolation == "linear"
    named, _ = retarget(cs, [0.0, 0.1, 0.2], m, m, neutral=2, fps=10)
    assert named.value("jaw.open", 0.2) == pytest.approx(0.0, abs=1e-6)


def test_across_head_models_by_name(builtin_model):
    m = builtin_model
    names = list(m.expr_names)
    names[names.index("smile_L")] = "mouthSmileLeft"  # another model's name for it: not matched
    other = replace(m, name="other", expr_names=tuple(names))
    mapping, missing, note = expression_map(m, other)
    assert missing == ["smile_L"] and len(mapping) == m.num_expression - 1 and not note
    anim, how = retarget(frames(m, m.num_expression), [0.0, 0.1, 0.2], m, other, fps=10)
    assert "expression.mouthSmileLeft" not in anim.tracks and "expression.smile_R" in anim.tracks
    assert how.missing == ["smile_L"]
    unnamed = replace(m, name="flame-like", expr_names=())
    anim, how = retarget(frames(m, m.num_expression), [0.0, 0.1, 0.2], m, unnamed, fps=10)
    assert "unnamed" in how.note and not any(c.startswith("expression.") for c in anim.tracks)
    assert anim.value("jaw.open", 0.0) == pytest.approx(math.degrees(0.2), abs=1e-4)  # jaw, gaze, head still go


def test_reenact_a_real_video(tmp_path, face_video, landmarker, capsys, gl):
    """The first 1.5 s of a real video at 10 frames a second drive the demo avatar: the mp4's left half is the
    video's crop, its right half the avatar's render of the saved animation, frame for frame."""
    from app.animation import animation_frames, check_channels, load_animation
    from app.cli import main
    from models.avatars.registry import load_avatar
    from models.tracking.video import Crop, sampled_frames
    from render.gl.raster import Rasterizer

    out = tmp_path / "perf.mp4"
    assert main(["reenact", str(DEMO), str(face_video), "--out", str(out), "--landmarker", str(landmarker),
                 "--seconds", "1.5", "--fps", "10", "--size", "64"]) == 0
    said = capsys.readouterr().out
    assert "driver's neutral frame" in said and "s a frame" in said
    report = json.loads((tmp_path / "perf_report.json").read_text())
    anim = load_animation(tmp_path / "perf.json")
    avatar = load_avatar(DEMO)[0]
    check_channels(anim, avatar.head_model, "perf.json")
    video = mp4_frames(out)
    assert len(video) == anim.frames == report["frames_written"] == 15 and video[0].shape == (64, 128, 3)
    source = {k: rgb for k, _, rgb in sampled_frames(face_video, 10) if k in report["source_frames"]}
    crop = Crop(report["crop"]["x0"], report["crop"]["y0"], report["crop"]["side"], 64)
    own = [resized(f, 64) for f in animation_frames(avatar, Rasterizer(gl), anim, 64, "preview")]
    for j in (0, 7, 14):
        assert psnr(video[j][:, :64], crop.image(source[report["source_frames"][j]])) > 28
        assert psnr(video[j][:, 64:], own[j]) > 30
    # the driver moved: the avatar's frames differ from its neutral frame's somewhere, and the neutral frame is rest
    n = report["neutral_frame"]
    assert max(np.abs(own[j].astype(int) - own[n]).max() for j in range(15)) > 40
    assert all(abs(anim.value(c, n / anim.fps)) < 1e-5 for c in anim.tracks if not c.startswith("camera."))
    alone = tmp_path / "alone.mp4"
    assert main(["reenact", str(DEMO), str(face_video), "--out", str(alone), "--landmarker", str(landmarker),
                 "--seconds", "1.0", "--fps", "10", "--size", "32", "--no-side-by-side", "--meshes", "obj"]) == 0
    assert mp4_frames(alone)[0].shape == (32, 32, 3)
    objs = sorted((tmp_path / "alone_meshes").iterdir())  # the guide mesh of every frame, for other tools
    assert len(objs) == 10 and objs[0].name == "frame_0000.obj"
    import trimesh

    assert len(trimesh.load(objs[3], process=False).vertices) == avatar.head_model.num_vertices


def test_reenact_refuses_what_it_cannot_use(tmp_path, face_video, landmarker, capsys):
    from app.cli import main

    mine = tmp_path / "perf.json"
    mine.write_text('{"my": "notes"}')
    args = ["reenact", str(DEMO), str(face_video), "--landmarker", str(landmarker), "--seconds", "0.5"]
    assert main([*args, "--out", str(tmp_path / "perf.mp4")]) == 2
    assert "perf.json" in capsys.readouterr().err and mine.read_text() == '{"my": "notes"}'
    assert main([*args, "--out", str(tmp_path / "perf.gif")]) == 2
    assert main(["reenact", str(DEMO), str(tmp_path / "none.mp4"), "--out", str(tmp_path / "x.mp4"),
                 "--landmarker", str(landmarker)]) == 2
    assert "none.mp4" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["perf.json"]


def test_cancel_leaves_no_video(tmp_path, face_video, landmarker):
    """SIGTERM (the studio's Cancel) while frames render: exit 130, and no mp4 or partial file is left."""
    out = tmp_path / "perf.mp4"
    proc = subprocess.Popen([sys.executable, "-m", "app.cli", "reenact", str(DEMO), str(face_video), "--out", str(out),
                             "--landmarker", str(landmarker), "--seconds", "1.5", "--size", "128"], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:
        if "driver's neutral frame" in line:  # printed as the rendering starts
            proc.send_signal(signal.SIGTERM)
            break
    rest = proc.communicate(timeout=120)[0]
    assert proc.returncode == 130, rest
    assert list(tmp_path.iterdir()) == []


def test_drive_an_avatar_from_another_persons_frames(tmp_path, gl, capsys):
    """"Drive B from A's frames": a capture (or the avatar folder trained on it) drives the demo; each frame's
    expression is the capture frame's less its calmest frame's, and the video's left half is the capture's image.
    The capture is of another person of the demo's head model (ICT's names on both sides)."""
    from app.animation import load_animation
    from app.cli import main
    from app.reenact import capture_of
    from models.capture.dataset import load_split
    from models.capture.frames import load_rgb
    from models.capture.synthetic import SynthConfig, synthesize
    from models.head.sources import load_head

    capture = tmp_path / "capture"
    head = load_head("demo")
    synthesize(SynthConfig(head="demo", identity=11, scene="sun", frames=12, size=32, out=capture), head, gl)
    out = tmp_path / "ab.mp4"
    assert main(["reenact", str(DEMO), str(capture), "--out", str(out), "--size", "32", "--fps", "10"]) == 0
    assert "reading the capture" in capsys.readouterr().out
    split = load_split(capture, "train")
    anim = load_animation(tmp_path / "ab.json")
    n = calmest_frame([f.controls for f in split.frames])
    assert split.head_model == "demo"
    spread = np.ptp([f.controls.expression[:head.num_expression] for f in split.frames], axis=0)
    names = [head.expr_names[i] for i in np.argsort(-spread)[:3]]  # the three shapes the script moves most
    index = {name: head.expression_index(name) for name in names}
    moved = 0
    for k, f in enumerate(split.frames):
        for name in names:
            want = float(np.clip(f.controls.expression[index[name]] - split.frames[n].controls.expression[index[name]],
                                 -1.0, 1.5))
            moved += abs(want) > 0.05
            assert anim.value(f"expression.{name}", k / 10) == pytest.approx(want, abs=1e-5)
    assert moved >= 3  # the script moves these shapes: the comparison is not of zeros
    video = mp4_frames(out)
    assert len(video) == len(split.frames) == anim.frames
    truth = (np.clip(load_rgb(split.frames[3].image_path, np.asarray(split.background, np.float32)), 0, 1) * 255)
    assert psnr(video[3][:, :32], truth.round().astype(np.uint8)) > 25
    # an avatar folder stands for the capture it was trained on, where that is on this machine
    folder = tmp_path / "anna"
    folder.mkdir()
    (folder / "avatar.json").write_text(json.dumps({"provenance": {"dataset": str(capture)}}))
    assert capture_of(folder) == capture
    (folder / "avatar.json").write_text(json.dumps({"provenance": {"dataset": str(tmp_path / "gone")}}))
    assert main(["reenact", str(DEMO), str(folder), "--out", str(tmp_path / "x.mp4")]) == 2
    assert "not on this machine" in capsys.readouterr().err
