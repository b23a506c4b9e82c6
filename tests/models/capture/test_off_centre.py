"""A capture whose principal point is off the image centre (a crop of a larger frame, as `track` writes for a
face near the frame's edge) trains, renders and evaluates; a frame's camera from the cropped capture sees the
same pixels as the original frame's camera where they overlap."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from app.avatar_commands import EvalConfig, run_eval
from models.avatars.rendering import RenderOptions, render_image
from models.capture.dataset import load_split
from models.capture.frames import frame_camera
from models.training.trainer import TrainConfig, prepare_training
from render.gl.raster import Rasterizer

pytestmark = pytest.mark.gl
LEFT, TOP, W, H = 3, 9, 26, 20


def crop_capture(src: Path, dst: Path) -> None:
    """The capture's images and masks cropped to [TOP:TOP+H, LEFT:LEFT+W], with the intrinsics moved to match."""
    for split in ("train", "val", "test"):
        data = json.loads((src / f"transforms_{split}.json").read_text())
        fx, fy, cx, cy = data["intrinsics"]
        data.update(intrinsics=[fx, fy, cx - LEFT, cy - TOP], width=W, height=H)
        data["camera_angle_x"] = 2 * np.arctan(0.5 * W / fx)
        for f in data["frames"]:
            for key in ("file_path", "mask_path"):
                out = dst / f[key]
                out.parent.mkdir(parents=True, exist_ok=True)
                Image.open(src / f[key]).crop((LEFT, TOP, LEFT + W, TOP + H)).save(out)
            for key in ("normal_path", "shadow_path", "depth_path", "albedo_path", "unshadowed_path", "bbox"):
                f.pop(key, None)
        (dst / f"transforms_{split}.json").write_text(json.dumps(data))


def test_off_centre_capture_trains_and_sees_the_same_pixels(synth_capture, gl, tmp_path):
    src = synth_capture("studio", 16, 32)
    dst = tmp_path / "cropped"
    crop_capture(src, dst)
    split = load_split(dst, "train")
    cam = frame_camera(split, split.frames[0])
    assert not cam.centred and cam.intrinsics[2:] == (16.0 - LEFT, 16.0 - TOP)
    t = prepare_training(TrainConfig(dataset=dst, out=tmp_path / "avatar", effects="none", steps=30,
                                     rays_per_step=256, checkpoint_seconds=1e9), gl)
    first = t.train_step(0.0)["photometric"]
    for k in range(1, 30):
        last = t.train_step(k / 30)["photometric"]
    assert np.isfinite(last) and last < first
    t.save()
    original = load_split(src, "train")
    f = original.frames[0]
    r = Rasterizer(gl)
    full = render_image(t.avatar.eval(), frame_camera(original, f), f.controls, RenderOptions(frame=0), r)["rgb"]
    part = render_image(t.avatar, cam, f.controls, RenderOptions(frame=0), r)["rgb"]
    # Away from the crop's border (the rendered pixels are the mesh's silhouette grown by a few pixels, and the
    # crop does not see the silhouette beyond its border), the same pixels.
    m = 4
    np.testing.assert_allclose(part[m:-m, m:-m], full[TOP:TOP + H, LEFT:LEFT + W][m:-m, m:-m], atol=1e-5)
    r.release()
    assert run_eval(EvalConfig(avatar=tmp_path / "avatar", dataset=dst, out=tmp_path / "eval")) == 0
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())["metrics"]
    assert np.isfinite(metrics["psnr"]) and metrics["psnr"] > 10
