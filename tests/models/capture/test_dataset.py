"""Capture datasets: our format validated on load, NerFACE's and IMavatar's imported, errors naming the
file, the frame and the field (exit status 2 from the CLI)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from app.cli import main
from models.capture.dataset import DatasetError, load_split
from models.head.lbs import rotation_matrix_from_axis_angle


def write_images(folder: Path, names: list[str], size=(40, 30)) -> None:
    for n in names:
        p = folder / n
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(np.full((size[1], size[0], 3), 128, np.uint8)).save(p)


def camera_to_world(yaw: float) -> list:
    m = np.eye(4)
    m[:3, :3] = rotation_matrix_from_axis_angle(__import__("torch").tensor([0.0, yaw, 0.0])).numpy()
    m[:3, 3] = [math.sin(yaw), 0, math.cos(yaw)]
    return m.tolist()


@pytest.fixture
def ours(tmp_path):
    write_images(tmp_path, [f"images/{k}.png" for k in range(3)])
    header = {"camera_angle_x": 0.5, "intrinsics": [50.0, 50.0, 20.0, 15.0], "width": 40, "height": 30,
              "head_model": "builtin", "shape": [0.5], "background": [1, 1, 1]}
    frames = [{"file_path": f"images/{k}.png", "transform_matrix": camera_to_world(0.1 * k),
               "expression": [0.1 * k], "controls": {"expression": [0.1 * k], "pose": {"jaw": [0.1, 0, 0]}}}
              for k in range(3)]
    for split in ("train", "val", "test"):
        (tmp_path / f"transforms_{split}.json").write_text(json.dumps({**header, "frames": frames}))
    return tmp_path


def test_loads_ours(ours):
    s = load_split(ours, "train")
    assert s.source_format == "avatar-studio" and s.trains_codynerf
    assert len(s.frames) == 3 and s.intrinsics == (50.0, 50.0, 20.0, 15.0)
    np.testing.assert_allclose(s.frames[2].controls.expression, [0.2])
    np.testing.assert_allclose(s.frames[1].controls.jaw, [0.1, 0, 0])
    np.testing.assert_allclose(s.frames[0].controls.shape, [0.5])
    assert all(f.time_s is None for f in s.frames)  # not a video's frames


def test_a_video_frames_time_is_read(ours):
    path = ours / "transforms_train.json"
    data = json.loads(path.read_text())
    for k, f in enumerate(data["frames"]):
        f.update(source_frame=3 * k, time_s=0.1 * k)
    path.write_text(json.dumps(data))
    assert [f.time_s for f in load_split(ours, "train").frames] == [0.0, 0.1, 0.2]


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d["frames"][1].pop("controls"), "frame 1: field 'controls' is missing"),
    (lambda d: d["frames"][2].update(transform_matrix=[[1, 0], [0, 1]]), "frame 2: field 'transform_matrix' must be"),
    (lambda d: d["frames"][0].update(transform_matrix=(np.eye(4) * 2).tolist()), "rigid camera-to-world"),
    (lambda d: d["frames"][1].update(file_path="images/9.png"), "frame 1: field 'file_path' file 'images/9.png'"),
    (lambda d: d["frames"][1].update(file_path="../../etc/passwd"), "points outside the dataset folder"),
    (lambda d: d["frames"][0]["controls"].update(pose={"jaw": [1, 2]}), "frame 0: field 'controls': pose.jaw"),
    (lambda d: d.update(head_model="smpl"), "field 'head_model' must be builtin"),
    (lambda d: d.pop("width"), "field 'width' is missing"),
    (lambda d: d["frames"][0].update(bbox=[0.5, 0.2, 0, 1]), "frame 0: field 'bbox'"),
    (lambda d: d["frames"][2].update(intrinsics=[0.0, 50, 20, 15]), "frame 2: field 'intrinsics' must be [fx, fy"),
    (lambda d: d["frames"][1].update(intrinsics=[50, 50, 20]), "frame 1: field 'intrinsics' must have shape"),
    (lambda d: d.update(background_intrinsics=[50, 50, 20, 15]), "field 'background_intrinsics' needs a background"),
    (lambda d: d["frames"][2].update(time_s=-0.5), "frame 2: field 'time_s' must be a number of seconds from 0"),
    (lambda d: d["frames"][1].update(time_s="0:01"), "frame 1: field 'time_s' must be a number of seconds"),
])
def test_errors_name_file_frame_field(ours, edit, message):
    path = ours / "transforms_train.json"
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    with pytest.raises(DatasetError, match="transforms_train.json: .*" + message.replace("(", r"\(").replace(
            "[", r"\[").replace(".", r"\.")):
        load_split(ours, "train")


def test_a_frame_of_its_own_intrinsics_has_its_own_camera(ours):
    """A following crop's frame: its own principal point (the others keep the split's), and its camera's rays are
    the split camera's shifted by the whole pixels between them."""
    from models.capture.frames import camera_of, frame_camera
    from render.rays import pixel_rays

    path = ours / "transforms_train.json"
    data = json.loads(path.read_text())
    data["frames"][1]["intrinsics"] = [50.0, 50.0, 20.0 - 6, 15.0 + 2]
    path.write_text(json.dumps(data))
    s = load_split(ours, "train")
    assert s.frames[0].intrinsics is None and s.frame_intrinsics(s.frames[1]) == (50.0, 50.0, 14.0, 17.0)
    own = pixel_rays(frame_camera(s, s.frames[1]))[1]
    shared = pixel_rays(camera_of(s, s.frames[1].camera_to_world))[1]
    np.testing.assert_allclose(own[2:, :34], shared[:-2, 6:], atol=1e-12)  # its pixel (x, y) is the split's (x+6, y-2)
    assert frame_camera(s, s.frames[0]).intrinsics == (50.0, 50.0, 20.0, 15.0)


def test_cli_exit_2_on_bad_dataset(ours, capsys):
    (ours / "transforms_val.json").write_text("{ not json")
    assert main(["dataset", str(ours)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "transforms_val.json: not valid JSON" in err[0]


def test_imports_nerface(tmp_path):
    write_images(tmp_path, [f"train/f_{k:04d}.png" for k in range(2)], size=(64, 48))
    frames = [{"file_path": f"./train/f_{k:04d}", "transform_matrix": camera_to_world(0.0),
               "expression": list(np.linspace(0, 1, 76) * k), "bbox": [0.1, 0.9, 0.2, 0.8]} for k in range(2)]
    (tmp_path / "transforms_train.json").write_text(json.dumps({"camera_angle_x": 0.6, "frames": frames}))
    s = load_split(tmp_path, "train")
    assert s.source_format == "nerface" and s.head_model is None and not s.trains_codynerf
    assert (s.width, s.height) == (64, 48)
    fx = 0.5 * 64 / math.tan(0.3)
    np.testing.assert_allclose(s.intrinsics, (fx, fx, 32, 24))
    assert s.frames[1].expression.shape == (76,) and s.frames[1].image_path.name == "f_0001.png"
    frames[1]["expression"] = [0.0] * 50
    (tmp_path / "transforms_train.json").write_text(json.dumps({"camera_angle_x": 0.6, "frames": frames}))
    with pytest.raises(DatasetError, match="frame 1: field 'expression' must have 76 values, got 50"):
        load_split(tmp_path, "train")


def test_imports_imavatar(tmp_path):
    write_images(tmp_path, [f"image/{k}.png" for k in range(1, 21)], size=(50, 50))
    w2c = np.linalg.inv(np.asarray(camera_to_world(0.3)))[:3]
    frames = [{"file_path": f"./image/{k}", "world_mat": w2c.tolist(), "expression": [0.01 * k] * 50,
               "pose": list(np.arange(15) * 0.01 + k * 0.001)} for k in range(1, 21)]
    (tmp_path / "flame_params.json").write_text(json.dumps({"intrinsics": [-4.0, 4.0, 0.5, 0.5],
                                                            "shape_params": [0.1] * 100, "frames": frames}))
    train, test = load_split(tmp_path, "train"), load_split(tmp_path, "test")
    assert train.source_format == "imavatar" and train.head_model == "flame"
    assert len(test.frames) == 2 and len(train.frames) + len(load_split(tmp_path, "val").frames) == 18
    np.testing.assert_allclose(train.intrinsics, (200, 200, 25, 25))
    f = train.frames[0]
    np.testing.assert_allclose(f.camera_to_world, camera_to_world(0.3), atol=1e-9)
    np.testing.assert_allclose(f.controls.jaw, np.array([0.06, 0.07, 0.08]) + 0.002, atol=1e-7)
    np.testing.assert_allclose(f.controls.gaze_right, np.array([0.12, 0.13, 0.14]) + 0.002, atol=1e-7)
    frames[3].pop("pose")
    (tmp_path / "flame_params.json").write_text(json.dumps({"intrinsics": [4.0, 4.0, 0.5, 0.5],
                                                            "shape_params": [0.1] * 100, "frames": frames}))
    with pytest.raises(DatasetError, match=r"flame_params\.json: frame 3: field 'pose' is missing"):
        load_split(tmp_path, "train")
