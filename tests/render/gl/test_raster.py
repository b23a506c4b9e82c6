"""Rasterized per-pixel geometry: triangle ids, depth and barycentrics against hand-computed values and
against the preview's depth buffer."""

from __future__ import annotations

import numpy as np
import pytest

from render.camera import Camera, framing_camera, look_at
from render.gl.preview import MeshFrame, PreviewRenderer, PreviewSettings
from render.gl.raster import Rasterizer
from render.rays import pixel_rays

pytestmark = pytest.mark.gl


def test_plane_hand_worked(gl):
    # Two triangles covering z = 0 in [-1, 1]^2, camera 2 m away on +z with a 90 degree field of view:
    # the image spans [-2, 2] at the plane, so the quad covers the central half of each axis.
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    cam = Camera(look_at(np.array([0.0, 0, 2]), np.zeros(3)), 90.0, 16, 16)
    r = Rasterizer(gl).rasterize(v, f, cam)
    assert r.hit[4:12, 4:12].all() and not r.hit[:3].any() and not r.hit[:, 13:].any()
    np.testing.assert_allclose(r.depth[r.hit], 2.0, atol=1e-5)
    # Pixel (row 5, column 10): ray through (x, y) = ((10.5/16*2-1)*2, (1-5.5/16*2)*2) = (0.625, 0.625) at the
    # plane, above the diagonal y = x? equal, so take (row 6, col 10): (0.625, 0.375), below the diagonal:
    # triangle 0 (v0, v1, v2), barycentrics solve p = a v0 + b v1 + c v2: c = (y+1)/2 = 0.6875,
    # b = (x+1)/2 - c = 0.8125 - 0.6875 = 0.125, a = 1 - b - c = 0.1875.
    assert r.triangle[6, 10] == 0
    np.testing.assert_allclose(r.bary[6, 10], [0.1875, 0.125, 0.6875], atol=1e-5)
    # The barycentric point lies on the pixel's ray at the rasterized depth.
    origin, dirs = pixel_rays(cam)
    point = (v[f[r.triangle[6, 10]]] * r.bary[6, 10][:, None]).sum(0)
    np.testing.assert_allclose(point, origin + dirs[6, 10] * 2.0 / -dirs[6, 10, 2], atol=1e-5)


def test_depth_agrees_with_the_preview(gl, builtin_model):
    cam = framing_camera(builtin_model.template, 30, 10, width_px=96, height_px=80)
    r = Rasterizer(gl).rasterize(builtin_model.template, builtin_model.triangles, cam)
    p = PreviewRenderer(gl)
    p.render(MeshFrame(builtin_model.template, builtin_model.triangles), cam, PreviewSettings(samples=1, shadows=False),
             read_depth=True)
    assert np.array_equal(np.isfinite(p.last_depth), r.hit)
    np.testing.assert_allclose(r.depth[r.hit], p.last_depth[r.hit], atol=1e-4)
    # Every visible point reconstructed from triangle and barycentrics sits on its pixel ray at that depth.
    origin, dirs = pixel_rays(cam)
    fwd = -np.linalg.inv(cam.view)[:3, 2]
    pts = (builtin_model.template[builtin_model.triangles[r.triangle[r.hit]]] * r.bary[r.hit][..., None]).sum(1)
    t = r.depth[r.hit] / (dirs[r.hit] @ fwd)
    err = np.linalg.norm(pts - (origin + dirs[r.hit] * t[:, None]), axis=1)
    print("reconstruction error quantiles (50, 99, 100%) mm:", np.round(np.quantile(err, [0.5, 0.99, 1]) * 1e3, 3))
    # GL decides coverage in float32 with its own edge rules; on triangles seen edge-on a pixel centre can
    # fall a hair outside the chosen triangle, where the clipped barycentrics land on the nearest edge.
    assert np.quantile(err, 0.99) < 2e-4 and err.max() < 5e-3


def test_off_centre_crop_rasterizes_the_same_pixels(gl, builtin_model):
    """The head through a camera and through an off-centre crop of it (principal point moved, fx != fy): the
    same triangle ids and depths on the pixels they share (edges may differ in a pixel or two by rounding)."""
    base = framing_camera(builtin_model.template, 25, 5, width_px=64, height_px=56)
    fx, fy, cx, cy = base.intrinsics
    wide = Camera.from_intrinsics(base.view, fx * 1.2, fy, cx, cy, 64, 56, base.near_m, base.far_m)
    crop = wide.cropped(13, 9, 40, 38)
    r = Rasterizer(gl)
    full, part = r.rasterize(builtin_model.template, builtin_model.triangles, wide), \
        r.rasterize(builtin_model.template, builtin_model.triangles, crop)
    same = full.triangle[9:47, 13:53] == part.triangle
    assert same.mean() > 0.995 and part.hit.sum() > 300, same.mean()
    both = same & part.hit
    np.testing.assert_allclose(part.depth[both], full.depth[9:47, 13:53][both], atol=1e-5)
    r.release()


def test_coverage_is_the_rasters_triangles_and_depth(gl, builtin_model):
    """Rasterizer.coverage (what choosing the pixels to train reads) is the raster's triangle ids and depth, bit for
    bit, without its barycentrics and distances; every model's training pixels come out the same from either."""
    from models.avatars.nerface.avatar import face_box
    from render.rays import Coverage, Raster

    cam = framing_camera(builtin_model.template, 30, 10, width_px=96, height_px=80)
    raster = Rasterizer(gl)
    full = raster.rasterize(builtin_model.template, builtin_model.triangles, cam)
    cover = raster.coverage(builtin_model.template, builtin_model.triangles, cam)
    assert type(cover) is Coverage and isinstance(full, Coverage) and not isinstance(cover, Raster)
    np.testing.assert_array_equal(cover.triangle, full.triangle)
    np.testing.assert_array_equal(cover.depth, full.depth)
    assert 0.1 < cover.hit.mean() < 0.9 and np.isinf(cover.depth[~cover.hit]).all()
    np.testing.assert_array_equal(face_box(cover.hit, 3), face_box(full.hit, 3))  # NerFACE's
    from models.avatars.codynerf.avatar import RenderConfig, active_pixels
    from models.avatars.primitives.avatar import PrimitivesAvatar, PrimitivesConfig

    np.testing.assert_array_equal(active_pixels(RenderConfig(), cam, cover), active_pixels(RenderConfig(), cam, full))
    primitives = PrimitivesAvatar(builtin_model, PrimitivesConfig(grid=8, voxels=4), 1, np.zeros(3, np.float32))
    pixels = primitives.training_pixels(cam, cover)
    assert pixels.sum() > cover.hit.sum()  # the mesh's pixels and a margin about them
    np.testing.assert_array_equal(pixels, primitives.training_pixels(cam, full))
