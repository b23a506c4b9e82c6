"""The training frames in memory (models/training/data.py): what a step's rays are made of."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from models.avatars.primitives.avatar import PrimitivesAvatar, PrimitivesConfig
from models.capture.dataset import load_split
from models.capture.frames import frame_camera
from models.capture.synthetic import SynthConfig, synthesize
from models.head.sources import load_builtin
from models.training.data import build_frames
from render.gl.raster import Rasterizer
from render.rays import pixel_rays


@pytest.mark.gl
def test_a_frames_rays_are_its_cameras_and_its_raster_made_afresh(tmp_path, gl):
    """build_frames keeps no per-frame directions or rasters: each frame's rays, made from the camera's directions
    and the frame's rotation, are the pixel rays of that frame's camera (render.rays, through the inverse view
    matrix: to 1e-6), and its training pixels are what rasterizing the frame again gives, bit for bit; so are its
    surface distances for a model that reads the raster (CoDyNeRF's shell), while one that reads none (the
    primitives) gets none kept and its rays' distances infinite, as render_image gives them."""
    from models.avatars.codynerf.avatar import CoDyNeRFAvatar

    synthesize(SynthConfig(scene="ambient", frames=4, size=32, views=2, out=tmp_path / "c"), load_builtin(), gl)
    split = load_split(tmp_path / "c", "train")  # each frame from two cameras, in front and behind
    primitives = PrimitivesAvatar(load_builtin(), PrimitivesConfig(grid=8, voxels=2, width=16), len(split.frames),
                                  np.zeros(3, np.float32))
    codynerf = CoDyNeRFAvatar.for_capture(load_builtin(), len(split.frames), np.zeros(3, np.float32), (), None)
    raster = Rasterizer(gl)
    for avatar in (primitives, codynerf):
        fs = build_frames(split, avatar, gl)
        assert (fs.surface_t is None) == (not avatar.reads_raster)
        yaws = set()
        for k, f in enumerate(split.frames):
            cam = frame_camera(split, f)
            origin, dirs = pixel_rays(cam)
            rays = fs.rays(k, torch.arange(32 * 32))
            np.testing.assert_allclose(rays.origins.numpy(), np.broadcast_to(origin, (32 * 32, 3)), atol=1e-6)
            np.testing.assert_allclose(rays.directions.numpy(), dirs.reshape(-1, 3), atol=1e-6)
            r = raster.rasterize(fs.geometry[k].posed.numpy(), avatar.head_model.triangles, cam)
            distance = torch.from_numpy(r.distance.astype(np.float32)).reshape(-1)
            assert torch.equal(rays.surface_t, distance if avatar.reads_raster else torch.full_like(distance, np.inf))
            assert np.array_equal(fs.active_index[k].numpy(), np.flatnonzero(avatar.training_pixels(cam, r)))
            yaws.add(round(float(np.degrees(np.arctan2(f.camera_to_world[0, 2], f.camera_to_world[2, 2]))), 3))
        assert len(yaws) > 1  # the frames' cameras differ: each frame's own rotation is used
    raster.release()


@pytest.mark.gl
def test_a_frames_colours_are_load_rgbs_bit_for_bit(tmp_path, gl):
    """Frames are kept as their files' bytes and a step's colours made from them: the same float32 numbers load_rgb
    gives the whole image (bytes / 255), and where a file has alpha (one frame here, among opaque ones) its colours
    composited over the avatar's background as load_rgb composites them."""
    from PIL import Image

    from models.capture.frames import load_rgb

    synthesize(SynthConfig(scene="ambient", frames=3, size=24, out=tmp_path / "c"), load_builtin(), gl)
    split = load_split(tmp_path / "c", "train")
    path = split.frames[1].image_path
    rgb = np.asarray(Image.open(path).convert("RGB"))
    alpha = np.random.default_rng(0).integers(0, 256, rgb.shape[:2], dtype=np.uint8)
    Image.fromarray(np.dstack([rgb, alpha]), "RGBA").save(path)
    background = np.array([0.2, 0.7, 0.45], np.float32)
    avatar = PrimitivesAvatar(load_builtin(), PrimitivesConfig(grid=8, voxels=2, width=16), len(split.frames),
                              background)
    fs = build_frames(split, avatar, gl)
    assert fs.images.dtype == torch.uint8 and fs.images.shape[-1] == 4
    assert fs.active_index[0].dtype == torch.int32
    for k, f in enumerate(split.frames):
        expected = torch.from_numpy(load_rgb(f.image_path, background)).reshape(-1, 3)
        assert torch.equal(fs.target(k, torch.arange(24 * 24)), expected), k
    assert not torch.equal(fs.target(1, torch.arange(24 * 24)), torch.from_numpy(rgb / np.float32(255)).reshape(-1, 3))
