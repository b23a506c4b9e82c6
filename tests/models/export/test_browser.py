"""The demo's .glb in a real browser: headless Chromium (WebGL on SwiftShader) with three.js's GLTFLoader, through the
player page, against the project's own GL render of the same mesh and pose (render/gl's rasterizer, the texture looked
up at its barycentrics) through the same camera: the colour's mean absolute difference over the head's pixels and the
silhouettes' intersection over union. A texture turned over or mirrored, a wrong pose or a camera a few degrees off
fail them (checked below against the same screenshot)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from app.web import write_web_folder
from models.export.bake import texture_image
from models.head.controls import Controls
from models.head.head import Head
from render.camera import turntable_camera
from tests.browser import player_page, show_through, snapshot, three_or_skip

PX = 256
MOUTH_POSE = ({"mouthStretch": 1.0, "smile_R": 0.7}, 15.0)
"""Morph weights and the jaw's opening (degrees) of the posed case."""
MAD_MAX, MOVED_MAD_MAX, IOU_MIN = 2.0, 5.0, 0.99
"""Tolerances, colour in 0..255. Measured (SwiftShader, Chromium 156, three.js r187): MAD 0.5-0.9 over the head,
0.8-1.8 over the pixels the pose moves, IoU 0.996 (three.js filters the texture through mipmaps in linear light, the
reference bilinearly on the 8-bit values; antialiased edges). Wrong: a texture turned over 35-40, mirrored 64-69;
the neutral pose where the mouth is open 38-41 over the moved pixels; a camera turned 4 degrees 6.9-7.8 (IoU
0.982-0.988)."""


@pytest.fixture(scope="module")
def browser(demo_export, tmp_path_factory):
    three_or_skip()
    folder = tmp_path_factory.mktemp("web") / "demo"
    write_web_folder(folder, demo_export[0].data)
    with player_page(folder) as page:
        yield page


def posed_vertices(head, weights: dict[str, float], jaw_deg: float) -> np.ndarray:
    """(V,3) the head model posed by its own skinning: the truth the file's morph targets and skin must reproduce."""
    expression = np.zeros(head.num_expression, np.float32)
    for name, w in weights.items():
        expression[head.expression_index(name)] = w
    with torch.no_grad():
        controls = Controls(expression=expression, jaw=np.float32([math.radians(jaw_deg), 0, 0]))
        return Head(head).pose(controls)[0][0].numpy()


def gl_render(raster, chart, vertices: np.ndarray, camera, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The project's GL render of the textured mesh: (H,W,3) colour in 0..255 and (H,W) where the mesh is."""
    r = raster.rasterize(vertices[chart.vertex_of], chart.triangles, camera)
    return 255 * texture_image(r, chart.uv, chart.triangles, image).astype(np.float64), r.hit


def scores(rgb, seen, ref, hit, moved) -> tuple[float, float, float]:
    """Mean absolute difference over the pixels both show the head, the same over `moved`, silhouette IoU."""
    both = seen & hit
    moved = moved & both
    moved_mad = float(np.abs(rgb[moved] - ref[moved]).mean()) if moved.any() else 0.0
    return float(np.abs(rgb[both] - ref[both]).mean()), moved_mad, float(both.sum() / (seen | hit).sum())


@pytest.mark.parametrize("posed", [False, True], ids=["neutral", "mouth_open"])
@pytest.mark.parametrize(("yaw_deg", "pitch_deg"), [(0.0, 0.0), (25.0, 5.0)])
def test_three_js_draws_the_glb_as_the_projects_gl_render_does(browser, demo_export, demo_avatar, raster, posed,
                                                               yaw_deg, pitch_deg):
    done = demo_export[0]
    head, chart, image = demo_avatar.head_model, done.chart, done.texture.image
    weights, jaw_deg = MOUTH_POSE if posed else ({}, 0.0)
    camera = turntable_camera(head.template, yaw_deg, pitch_deg, width_px=PX, height_px=PX)
    show_through(browser, camera)
    browser.evaluate("window.player.neutral()")
    for name, w in weights.items():
        browser.evaluate(f"window.player.setWeight('{name}', {w})")
    if jaw_deg:
        browser.evaluate(f"window.player.setJawDeg({jaw_deg})")
    rgb, seen = snapshot(browser)

    ref, hit = gl_render(raster, chart, posed_vertices(head, weights, jaw_deg), camera, image)
    neutral, neutral_hit = gl_render(raster, chart, posed_vertices(head, {}, 0.0), camera, image)
    moved = (np.abs(ref - neutral).max(-1) > 30) | (hit != neutral_hit)  # the pixels the pose changes
    assert moved.sum() > (800 if posed else -1) and (posed or not moved.any())
    mad, moved_mad, iou = scores(rgb, seen, ref, hit, moved)
    assert mad < MAD_MAX and moved_mad < MOVED_MAD_MAX and iou > IOU_MIN, (mad, moved_mad, iou)

    # The same screenshot against what a wrong file or viewer would show fails the tolerances.
    for wrong_image in (image[::-1], image[:, ::-1]):  # v turned over, u mirrored
        assert scores(rgb, seen, *gl_render(raster, chart, posed_vertices(head, weights, jaw_deg), camera,
                                            wrong_image), moved)[0] > 5 * MAD_MAX
    if posed:
        assert scores(rgb, seen, neutral, neutral_hit, moved)[1] > 4 * MOVED_MAD_MAX
    off = turntable_camera(head.template, yaw_deg + 4.0, pitch_deg, width_px=PX, height_px=PX)
    wrong = scores(rgb, seen, *gl_render(raster, chart, posed_vertices(head, weights, jaw_deg), off, image), moved)
    assert wrong[0] > 3 * MAD_MAX and wrong[2] < IOU_MIN, wrong
