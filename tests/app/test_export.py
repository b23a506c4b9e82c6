"""`avatar-studio export`: the command end to end, and an animation file's keys carried into glTF samplers."""

from __future__ import annotations

import json
import re

import numpy as np
import pygltflib
import pytest
from scipy.spatial.transform import Rotation

from app.animation import Animation, load_animation, rest_sliders
from app.cli import main
from app.export import animation_clip
from app.sliders import View
from models.export.keys import channel_samples
from models.head.controls import ControlsError
from tests.conftest import DEMO
from tests.models.export.reading import accessor, cubic_spline, validator_report

TALK = {"format": "avatar-studio/animation/1", "fps": 10, "duration_s": 2.0, "interpolation": "smooth",
        "tracks": {"expression.smile_L": [[0, 0], [0.8, 0.9], [2, 0.2]], "expression.blink_R": [[0.4, 0], [0.6, 1]],
                   "jaw.open": [[0, 0], [1, 15]], "head.yaw": [[0, -10], [2, 10]], "camera.yaw": [[0, 20], [2, -20]]}}
#: The same talk in the demo's head model's terms (ICT's names; its mouth opens through jawOpen, it has no jaw joint).
TALK_ICT = {**TALK, "tracks": {"expression.mouthSmile_L": TALK["tracks"]["expression.smile_L"],
                               "expression.eyeBlink_R": TALK["tracks"]["expression.blink_R"],
                               "expression.jawOpen": [[0, 0], [1, 0.6]], "head.yaw": TALK["tracks"]["head.yaw"],
                               "camera.yaw": TALK["tracks"]["camera.yaw"]}}


def write(tmp_path, data: dict, name: str = "talk.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def test_export_writes_a_valid_glb_whose_animation_carries_the_files_keys(tmp_path, capsys):
    """The demo (an ICT-FaceKit identity): every vertex of its head model once and its chart's seam copies again,
    a morph target per expression, the joints ICT has (root and the eyes); the file's keys, in morph weights, at
    the file's times; the head's turn on the root."""
    from models.head.sources import load_head

    head = load_head(json.loads((DEMO / "avatar.json").read_text())["head_model"])
    out = tmp_path / "demo.glb"
    argv = ["export", str(DEMO), "--out", str(out), "--texture-size", "64", "--render-size", "64", "--views", "1",
            "--animation", str(write(tmp_path, TALK_ICT))]
    assert main(argv) == 0
    said = capsys.readouterr().out
    vertices, seams = map(int, re.search(r"(\d+) vertices of which (\d+) seam copies", said).groups())
    E = head.num_expression
    assert vertices - seams == len(head.template) and 0 < seams < len(head.template) // 2  # xatlas's seams: 5356
    assert f"{E} morph targets" in said and "camera.yaw left out" in said
    gltf = pygltflib.GLTF2.load(str(out))
    (anim,) = gltf.animations
    assert anim.name == "talk"
    weights = next(c for c in anim.channels if c.target.path == "weights")
    sampler = anim.samplers[weights.sampler]
    t = accessor(gltf, sampler.input)[:, 0]
    np.testing.assert_array_equal(t, np.float32([0, 0.4, 0.6, 0.8, 1, 2]))  # the keys' times, every channel's
    out3 = accessor(gltf, sampler.output).reshape(len(t), 3, E)
    names = gltf.meshes[0].extras["targetNames"]
    smile, blink, jaw = names.index("mouthSmile_L"), names.index("eyeBlink_R"), names.index("jawOpen")
    np.testing.assert_allclose(out3[[0, 3, 5], 1, smile], [0, 0.9, 0.2], atol=1e-7)  # the file's values at its keys
    np.testing.assert_allclose(out3[[1, 2], 1, blink], [0, 1], atol=1e-7)
    np.testing.assert_allclose(out3[[0, 4], 1, jaw], [0, 0.6], atol=1e-7)
    turning = {gltf.nodes[c.target.node].name for c in anim.channels if c.target.path == "rotation"}
    assert turning == {"root"}
    report = validator_report(out)
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["messages"]


@pytest.mark.parametrize("interpolation", ["smooth", "linear"])
def test_played_as_glTF_plays_it_the_clip_is_the_animation(builtin_model, interpolation):
    """The morph sampler at any time equals app/animation.py's Animation.value (smooth: glTF's cubic spline with the
    tangents written; linear: straight lines between the keys), and each frame's joint rotation is the sliders'."""
    anim = load_animation_dict(TALK | {"interpolation": interpolation})
    clip = animation_clip(anim, builtin_model, "talk")
    m = clip.morph
    assert m.interpolation == ("CUBICSPLINE" if interpolation == "smooth" else "LINEAR")
    out = np.stack([m.in_tangents, m.values, m.out_tangents], 1)
    smile = builtin_model.expression_index("smile_L")
    for t in np.linspace(-0.3, 2.3, 131):
        if interpolation == "smooth":
            got = cubic_spline(m.times, out, t)[smile]
        else:
            got = np.interp(t, m.times, m.values[:, smile])
        assert got == pytest.approx(anim.value("expression.smile_L", t), abs=3e-6)
    np.testing.assert_allclose(clip.pose.times, anim.times(), atol=1e-7)
    for k, t in enumerate(anim.times()):
        controls = anim.pose_at(t, rest_sliders(builtin_model), View(), builtin_model)[0].controls()
        for joint, rotvec in ((0, controls.root), (2, controls.jaw)):  # root and jaw of the built-in head
            want = Rotation.from_rotvec(rotvec)
            got = Rotation.from_quat(clip.pose.rotations[joint][k])
            assert (want.inv() * got).magnitude() < 1e-6


def test_channel_samples_are_the_animations_values_with_repeated_and_unsorted_keys():
    rng = np.random.default_rng(3)
    for interpolation in ("smooth", "linear"):
        for _ in range(20):
            times = np.sort(np.round(rng.uniform(0, 3, 5), 1))  # repeated times happen at 0.1 s steps
            keys = tuple((float(t), float(v)) for t, v in zip(times, rng.normal(size=5), strict=True))
            anim = Animation(10.0, 3.0, interpolation, {"expression.0": keys})
            probe = np.linspace(-0.5, 3.5, 81)
            values = channel_samples(keys, probe, interpolation)[0]
            np.testing.assert_allclose(values, [anim.value("expression.0", t) for t in probe], atol=1e-12)


def test_a_rotation_the_head_model_cannot_make_is_named(ict_model):
    """ICT has no jaw joint (it opens the mouth through jawOpen): keying jaw.open is an error, as in `animate`."""
    with pytest.raises(ControlsError, match="'jaw'"):
        animation_clip(load_animation_dict({**TALK, "tracks": {"jaw.open": [[0, 0], [1, 10]]}}), ict_model, "x")


@pytest.mark.parametrize(("args", "line"), [
    (["--out", "{tmp}/a.gltf"], "{tmp}/a.gltf: output must end in .glb"),
    (["--animation", "{tmp}/bad.json"], "unknown channel 'mouth.open'"),
])
def test_bad_input_is_one_line_and_status_2(tmp_path, capsys, args, line):
    write(tmp_path, {**TALK, "tracks": {"mouth.open": [[0, 0]]}}, "bad.json")
    argv = ["export", str(DEMO), "--out", str(tmp_path / "x.glb"), *[a.format(tmp=tmp_path) for a in args]]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and line.format(tmp=tmp_path) in err[0]


def load_animation_dict(data: dict) -> Animation:
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "anim.json"
        path.write_text(json.dumps(data))
        return load_animation(path)
