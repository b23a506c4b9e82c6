"""Keyframed animation: interpolation worked by hand, the file's round trip and its errors, and `animate` writing
a video whose frames follow the keys."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from app.animation import Animation, AnimationError, channel_value, load_animation, rest_sliders, save_animation
from app.sliders import View
from models.head.sources import load_builtin, load_head
from tests.conftest import DEMO


def test_interpolation_by_hand():
    a = Animation(fps=10, duration_s=2.0, interpolation="linear", tracks={"jaw.open": ((0.0, 0.0), (1.0, 20.0))})
    assert a.value("jaw.open", -1.0) == 0.0 and a.value("jaw.open", 0.25) == 5.0 and a.value("jaw.open", 5.0) == 20.0
    smooth = Animation(fps=10, duration_s=2.0, interpolation="smooth", tracks=a.tracks)
    assert smooth.value("jaw.open", 0.25) == pytest.approx(20.0 * 0.15625)  # 3u^2 - 2u^3 at u = 1/4
    assert smooth.value("jaw.open", 0.5) == pytest.approx(10.0)
    # keys are kept in time order; a key at the same time replaces the old one
    b = a.with_key("jaw.open", 0.5, 4.0).with_key("jaw.open", 0.5, 6.0)
    assert b.tracks["jaw.open"] == ((0.0, 0.0), (0.5, 6.0), (1.0, 20.0))
    assert b.without_key("jaw.open", 0.5).tracks == a.tracks
    assert a.frames == 20 and a.times()[:3] == [0.0, 0.1, 0.2]


def test_poses_follow_the_channels():
    head = load_builtin()
    smile = head.expr_names[0]
    a = Animation(fps=4, duration_s=1.0, interpolation="linear",
                  tracks={f"expression.{smile}": ((0.0, 0.0), (1.0, 0.8)), "head.yaw": ((0.0, -20.0), (1.0, 20.0)),
                          "gaze.pitch": ((0.0, 10.0),), "camera.zoom": ((0.0, 1.0), (1.0, 2.0))})
    s, v = a.pose_at(0.5, rest_sliders(head), View(), head)
    assert channel_value(s, v, head, f"expression.{smile}") == pytest.approx(0.4)
    assert s.head[0] == pytest.approx(0.0) and v.zoom == pytest.approx(1.5)
    assert s.gaze_left[1] == s.gaze_right[1] == pytest.approx(10.0)
    c = s.controls()
    assert c.expression[0] == pytest.approx(0.4)


def test_the_file_round_trips_and_bad_files_name_the_problem(tmp_path):
    a = Animation(fps=24, duration_s=3.0, interpolation="smooth", tracks={"camera.yaw": ((0.0, 20.0), (3.0, -20.0))})
    save_animation(a, tmp_path / "a.json")
    assert load_animation(tmp_path / "a.json") == a
    bad = {"a list": [1, 2], "no format": {"duration_s": 1}, "nan key": {"format": "avatar-studio/animation/1",
           "duration_s": 1, "tracks": {"jaw.open": [[0, "nan"]]}}, "zero fps": {"format": "avatar-studio/animation/1",
           "duration_s": 1, "fps": 0}}
    for name, data in bad.items():
        (tmp_path / "b.json").write_text(json.dumps(data))
        with pytest.raises(AnimationError, match=r"b\.json") as e:
            load_animation(tmp_path / "b.json")
        assert str(e.value).count("\n") == 0, name  # one line


@pytest.mark.gl
def test_animate_writes_the_keyed_motion(tmp_path, capsys):
    from app.cli import main

    # the demo (ICT) opens its mouth through the jawOpen expression; a head with a jaw joint keys jaw.open
    anim = Animation(fps=4, duration_s=0.75, interpolation="linear",
                     tracks={"expression.jawOpen": ((0.0, 0.0), (0.5, 1.0))})
    save_animation(anim, tmp_path / "jaw.json")
    out = tmp_path / "jaw.mp4"
    assert main(["animate", str(DEMO), str(tmp_path / "jaw.json"), "--out", str(out), "--size", "48",
                 "--preset", "draft", "--meshes", "obj"]) == 0
    import trimesh

    meshes = sorted((tmp_path / "jaw_meshes").glob("frame_*.obj"))
    head = load_head(json.loads((DEMO / "avatar.json").read_text())["head_model"])
    first, last = (trimesh.load(m, process=False) for m in (meshes[0], meshes[-1]))
    assert len(meshes) == 3 and len(first.vertices) == head.num_vertices
    assert np.abs(last.vertices - first.vertices).max() > 0.005  # the guide's jaw opened too
    cap = cv2.VideoCapture(str(out))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f.astype(int))
    assert len(frames) == 3 == len(list((tmp_path / "jaw").glob("frame_*.png")))
    assert np.abs(frames[2] - frames[0]).max() > 40  # the mouth opened
    (tmp_path / "bad.json").write_text(json.dumps({**anim.to_json(), "tracks": {"expression.nope": [[0, 1]]}}))
    assert main(["animate", str(DEMO), str(tmp_path / "bad.json"), "--out", str(tmp_path / "x.mp4")]) == 2
    assert "nope" in capsys.readouterr().err
