"""Any pinhole camera, for every model: the same avatar rendered through a centred camera and through an
off-centre crop of the same view (principal point moved, fx != fy) gives the same pixels where they overlap."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from models.avatars.codynerf.avatar import silhouette_margin_px
from models.avatars.nerface.avatar import NerfaceAvatar, NerfaceConfig
from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.head.controls import Controls
from render.camera import Camera, framing_camera
from render.gl.raster import Rasterizer
from tests.conftest import CODYNERF_DEMO

pytestmark = pytest.mark.gl
LEFT, TOP, W, H = 11, 7, 38, 44


def cameras(template: np.ndarray) -> tuple[Camera, Camera]:
    """A 64x60 view with fx = 1.15 fy, and a crop of it whose principal point lies far off its centre."""
    base = framing_camera(template, 25.0, 5.0, fov_y_deg=18.0, width_px=64, height_px=60)
    fx, fy, cx, cy = base.intrinsics
    full = Camera.from_intrinsics(base.view, 1.15 * fx, fy, cx, cy, 64, 60, base.near_m, base.far_m)
    return full, full.cropped(LEFT, TOP, W, H)


def test_codynerf_crop_renders_the_same_pixels(gl):
    avatar, _ = load_avatar(CODYNERF_DEMO)
    full_cam, crop_cam = cameras(avatar.head_model.template)
    r = Rasterizer(gl)
    controls = Controls(jaw=np.array([0.2, 0.0, 0.0], np.float32))
    full = render_image(avatar, full_cam, controls, RenderOptions(inspect=True), r)
    crop = render_image(avatar, crop_cam, controls, RenderOptions(inspect=True), r)
    # Pixels within the silhouette margin of the crop's border may differ: which rays are rendered is the mesh's
    # silhouette grown by that margin, and the crop does not see the silhouette beyond its border.
    m = silhouette_margin_px(avatar.render_cfg, crop_cam, r.rasterize(avatar.frame_geometry(controls, r).posed.numpy(),
                                                                        avatar.head_model.triangles, crop_cam).depth)
    inner = (slice(m, H - m), slice(m, W - m))
    for name in ("rgb", "opacity", "normals", "rgb_no_shadows", "rgb_light", "rgb_flat"):
        a, b = full[name][TOP:TOP + H, LEFT:LEFT + W][inner], crop[name][inner]
        # The same rays (float64), the same triangles, the same distances along them (render/rays.py: met with the
        # triangle's plane, not read from the GL depth, whose last bits differ between the two projections).
        np.testing.assert_allclose(a, b, atol=1e-5, err_msg=name)
    assert (full["opacity"][TOP:TOP + H, LEFT:LEFT + W] > 0.5).mean() > 0.3  # the head fills the overlap
    r.release()


def test_nerface_crop_renders_the_same_pixels(gl, builtin_model):
    torch.manual_seed(0)
    avatar = NerfaceAvatar(builtin_model, NerfaceConfig(width=32, depth=2, coarse_samples=16, fine_samples=8), 1,
                           np.ones(3, np.float32)).eval()
    full_cam, crop_cam = cameras(builtin_model.template)
    full = render_image(avatar, full_cam, Controls(), rasterizer=None)
    crop = render_image(avatar, crop_cam, Controls(), rasterizer=None)
    for name in ("rgb", "opacity", "depth"):
        a, b = full[name][TOP:TOP + H, LEFT:LEFT + W], crop[name]
        finite = np.isfinite(a)
        assert np.array_equal(finite, np.isfinite(b))
        np.testing.assert_allclose(a[finite], b[finite], atol=1e-5)
