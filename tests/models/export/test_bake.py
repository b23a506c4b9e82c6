"""Texture baking: texels onto the surface, cameras and what they see, the views' blend, the fill; and the baked
texture drawn on the mesh against the avatar's own render."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from models.avatars.rendering import RenderOptions, render_image
from models.export.bake import (
    FEATHER_COS,
    ViewBlend,
    bake_texture,
    bake_views,
    project,
    sample_bilinear,
    texel_surface,
    texture_image,
)
from models.export.chart import head_chart
from models.head.controls import Controls
from render.camera import turntable_camera
from render.fill import push_pull
from render.rays import pixel_rays
from tests.conftest import CODYNERF_DEMO


def test_a_texel_claimed_twice_goes_to_the_triangle_wound_as_most_are():
    """Two triangles split the unit square along u + v = 1 (both wound one way); a third, wound the other way (as a
    triangle across a wrap-around seam is), lies over the first. Texel (r, c) of 4 has its centre at
    ((c + 0.5) / 4, (r + 0.5) / 4): below the diagonal (c + r < 3) the first triangle's, above it the second's."""
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32)
    tris = np.array([[0, 1, 2], [1, 3, 2], [0, 2, 1]])
    s = texel_surface(uv, tris, 4, reach_px=0.0)
    r, c = np.mgrid[0:4, 0:4]
    assert (s.triangle[r + c < 3] == 0).all() and (s.triangle[r + c > 3] == 1).all()
    assert not (s.triangle == 2).any()
    # Texel (0, 0): centre uv (1/8, 1/8) = 3/4 v0 + 1/8 v1 + 1/8 v2.
    np.testing.assert_allclose(s.bary[0, 0], [0.75, 0.125, 0.125])


def test_texels_just_outside_a_triangle_take_its_nearest_point():
    """A triangle covering texel centres up to u = 0.45 of an 8-texel row: texel 3's centre (u = 0.4375) is inside;
    texel 4's (0.5625, 0.9 texels past the edge) is within no reach of 0.75 texels; with reach 1 it is clamped on."""
    uv = np.array([[0, 0], [0.45, 0], [0.45, 1]], np.float32)
    tris = np.array([[0, 1, 2]])
    assert texel_surface(uv, tris, 8).triangle[7, 4] == -1
    s = texel_surface(uv, tris, 8, reach_px=1.0)
    assert s.triangle[7, 4] == 0
    assert (s.bary[7, 4] >= 0).all() and s.bary[7, 4].sum() == pytest.approx(1.0)
    assert s.bary[7, 4][0] == 0.0  # on the edge v1-v2, opposite v0


def test_push_pull_keeps_known_texels_and_fills_from_them():
    rng = np.random.default_rng(0)
    image = rng.random((37, 50, 3))
    known = rng.random((37, 50)) < 0.2
    out = push_pull(image, known)
    np.testing.assert_array_equal(out[known], image[known])
    assert np.isfinite(out).all()
    flat = push_pull(np.where(known[..., None], 0.3, 0.0), known)  # one colour known: everywhere that colour
    np.testing.assert_allclose(flat, 0.3, atol=1e-12)


def test_bilinear_lookup_matches_opencvs():
    rng = np.random.default_rng(1)
    image = rng.random((20, 30, 3)).astype(np.float32)
    x, y = rng.uniform(0.5, 29.5, 500), rng.uniform(0.5, 19.5, 500)
    ref = cv2.remap(image, (x - 0.5).astype(np.float32)[None], (y - 0.5).astype(np.float32)[None], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)[0]
    np.testing.assert_allclose(sample_bilinear(image, x, y), ref, atol=1e-3)  # OpenCV's weights are 5-bit fixed point


def test_a_surface_point_projects_to_the_pixel_whose_ray_met_it(demo_avatar, raster):
    camera = turntable_camera(demo_avatar.card.rest_vertices(), 30.0, 10.0, width_px=48, height_px=48)
    r = raster.rasterize(demo_avatar.card.rest_vertices(), demo_avatar.head_model.triangles, camera)
    origin, dirs = pixel_rays(camera)
    i, j = np.nonzero(r.hit)
    points = origin + dirs[i, j] * r.distance[i, j][:, None]
    x, y, depth = project(camera, points)
    np.testing.assert_allclose(x, j + 0.5, atol=1e-6)
    np.testing.assert_allclose(y, i + 0.5, atol=1e-6)
    np.testing.assert_allclose(depth, r.depth[i, j], atol=1e-5)


def test_views_blend_by_how_squarely_they_see_in_any_order():
    """cos 0.9 (red) and 0.87 (blue) weigh 1 and exp(-0.03 / 0.03) = 1/e; cos 0.1 (green) is below MIN_COS."""
    views = [(0.9, [1.0, 0, 0]), (0.1, [0, 1.0, 0]), (0.87, [0, 0, 1.0])]
    want = np.array([1.0, 0, 1 / math.e]) / (1 + 1 / math.e)
    assert FEATHER_COS == 0.03
    for order in ([0, 1, 2], [2, 1, 0], [1, 2, 0]):
        blend = ViewBlend(1)
        for k in order:
            blend.add(k, np.array([views[k][0]]), np.array([views[k][1]]))
        np.testing.assert_allclose(blend.colour()[0], want, atol=1e-6)
        assert blend.view[0] == 0
    assert ViewBlend(1).view[0] == -1


def test_the_bake_looks_only_where_the_avatar_has_seen(demo_avatar):
    """The demo's capture saw yaws -46.5..46 degrees, pitches -18.5..20.5: a turntable's 56.5 each side reaches 0.5
    past the captured -46.5 - 10 on one side, so the bake keeps to 56 each side."""
    assert bake_views(demo_avatar, 3) == [(-56.0, 0.0), (0.0, 0.0), (56.0, 0.0), (-56.0, 20.5), (56.0, 20.5),
                                          (0.0, -18.5)]
    assert not any(demo_avatar.card.views_beyond(y) for y, _ in bake_views(demo_avatar, 9))


def test_an_avatar_seen_all_round_is_baked_all_round():
    from models.avatars.registry import load_avatar

    avatar = load_avatar(CODYNERF_DEMO)[0]
    assert [y for y, p in bake_views(avatar, 4) if p == 0] == [-180.0, -90.0, 0.0, 90.0]


def textured_psnr(avatar, raster, chart, image: np.ndarray, yaw_deg: float, pitch_deg: float, px: int = 128) -> float:
    """PSNR (dB) of the guide mesh drawn with the texture (over the background as far as the render is background)
    against the avatar's own render at rest, over the pixels where both show the head."""
    camera = turntable_camera(avatar.card.rest_vertices(), yaw_deg, pitch_deg, width_px=px, height_px=px)
    ref = render_image(avatar, camera, avatar.card.at_rest(Controls()), RenderOptions(buffers=()), raster)
    r = raster.rasterize(avatar.card.rest_vertices()[chart.vertex_of], chart.triangles, camera)
    o = ref["opacity"][..., None]
    drawn = o * texture_image(r, chart.uv, chart.triangles, image) + (1 - o) * avatar.background.numpy()
    face = r.hit & (ref["opacity"] > 0.5)
    assert face.sum() > 0.2 * px * px
    return float(10 * np.log10(1.0 / np.mean((drawn[face] - ref["rgb"][face]) ** 2)))


@pytest.mark.parametrize(("yaw_deg", "pitch_deg", "least_db"), [(0.0, 0.0, 26.5), (20.0, 5.0, 26.0),
                                                                 (-35.0, 10.0, 23.5)])
def test_the_demos_texture_on_the_mesh_looks_like_its_render(demo_export, demo_avatar, raster, yaw_deg, pitch_deg,
                                                             least_db):
    """At the front (a bake camera's view) and between the bake's cameras, 128 px: measured 28.6, 28.0 and 25.4 dB
    (256 px texture, 6 renders of 128 px); a flat texture of the seen texels' mean colour scores 13.2-13.7 dB."""
    done = demo_export[0]
    got = textured_psnr(demo_avatar, raster, done.chart, done.texture.image, yaw_deg, pitch_deg)
    flat = np.broadcast_to(done.texture.image[done.texture.seen].mean(0).round().astype(np.uint8),
                           done.texture.image.shape)
    assert got > least_db
    assert textured_psnr(demo_avatar, raster, done.chart, flat, yaw_deg, pitch_deg) < least_db - 5


def test_most_of_the_demos_texels_are_seen(demo_export):
    """The demo was captured from the front only: the back of the head, the mouth's inside and the eyeballs' backs
    are filled. Measured: 69% of the chart's texels seen."""
    texture = demo_export[0].texture
    assert 0.6 < texture.seen_share < 0.8
    assert (texture.view[texture.seen] >= 0).all() and (texture.view[~texture.covered] == -1).all()


def test_a_codynerf_avatar_bakes_too(raster):
    """CoDyNeRF's shipped avatar is half see-through (opacity about 0.8 on the face): its colour is the render's
    with the background taken out. Measured 23 dB at the front (8 renders of 64 px, 128 px texture)."""
    from models.avatars.registry import load_avatar

    avatar = load_avatar(CODYNERF_DEMO)[0]
    chart = head_chart(avatar.head_model, 128)
    baked = bake_texture(avatar, chart, 128, 64, 4, raster)
    assert baked.seen_share > 0.8
    got = textured_psnr(avatar, raster, chart, baked.image, 0.0, 0.0, px=64)
    assert got > 20.0
