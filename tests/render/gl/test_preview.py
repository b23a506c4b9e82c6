"""The GL preview on small offscreen framebuffers: read-back pixels against hand-computed values, and
depth against pyrender, an independent renderer."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from render.camera import Camera, look_at
from render.gl.preview import MeshFrame, PreviewRenderer, PreviewSettings

W = H = 64


def quad(half: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], np.float32)
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def camera_at(z: float, fov: float = 60.0) -> Camera:
    return Camera(look_at(np.array([0.0, 0.0, z]), np.zeros(3)), fov, W, H)


FLAT = PreviewSettings(albedo=(0.5, 0.5, 0.5), ambient=(0.2, 0.2, 0.2), light_color=(0.6, 0.6, 0.6),
                       light_dir=(0.0, 0.0, 1.0), shadows=False, samples=1, background=(0.0, 0.0, 0.0))


@pytest.fixture
def renderer(gl):
    r = PreviewRenderer(gl)
    yield r
    r.release()


@pytest.mark.gl
def test_diffuse_hand_worked(renderer):
    v, f = quad(5.0, 0.0)
    img = renderer.render(MeshFrame(v, f), camera_at(1.0, 90.0), FLAT)
    # Light along the normal: 0.5 * (0.2 + 0.6 * 1) = 0.4 -> 0.4 * 255 = 102.
    assert np.abs(img.astype(int) - 102).max() <= 1
    tilted = PreviewSettings(**{**FLAT.__dict__, "light_dir": (math.sin(math.radians(60)), 0.0, 0.5)})
    img = renderer.render(MeshFrame(v, f), camera_at(1.0, 90.0), tilted)
    # At 60 degrees: 0.5 * (0.2 + 0.6 * cos 60) = 0.25 -> 63.75, stored as 64.
    assert np.abs(img.astype(int) - 64).max() <= 1


@pytest.mark.gl
def test_normals_as_colours(renderer):
    v, f = quad(5.0, 0.0)
    img = renderer.render(MeshFrame(v, f), camera_at(1.0, 90.0), PreviewSettings(pass_name="normals", samples=1))
    # n = (0, 0, 1) -> (0.5, 0.5, 1.0) * 255 = (127.5, 127.5, 255).
    assert np.abs(img[..., :2].astype(float) - 127.5).max() <= 1
    assert (img[..., 2] == 255).all()


@pytest.mark.gl
def test_depth_read_back(renderer):
    v, f = quad(5.0, 0.0)
    renderer.render(MeshFrame(v, f), camera_at(2.0), FLAT, read_depth=True)
    # Along the optical axis the plane is 2 m away; off axis the depth (along -z) is still 2 m.
    np.testing.assert_allclose(renderer.last_depth, 2.0, atol=1e-4)


def expected_shadow_mask() -> np.ndarray:
    """Per pixel centre: the ray from the camera (z = 2, fov 60) hits the back plane z = 0 in the shadow of
    the occluder [-0.1, 0.1]^2 at z = 0.2 under light direction (1, 0, 1)/sqrt 2, and not the occluder."""
    t = math.tan(math.radians(30))
    j, i = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    dx, dy = (j / W * 2 - 1) * t, (1 - i / H * 2) * t
    hits_occluder = (np.abs(1.8 * dx) <= 0.1) & (np.abs(1.8 * dy) <= 0.1)
    x, y = 2 * dx, 2 * dy  # on the back plane
    shadowed = (np.abs(x + 0.2) <= 0.1) & (np.abs(y) <= 0.1)  # the light ray rises 0.2 in x by z = 0.2
    return shadowed & ~hits_occluder


@pytest.mark.gl
def test_shadow_map_hand_worked(renderer):
    back_v, back_f = quad(2.0, 0.0)
    occ_v, occ_f = quad(0.1, 0.2)
    frame = MeshFrame(np.concatenate([back_v, occ_v]), np.concatenate([back_f, occ_f + 4]))
    settings = PreviewSettings(pass_name="shadow", light_dir=(1.0, 0.0, 1.0), shadows=True, samples=1,
                               shadow_map_px=1024)
    img = renderer.render(frame, camera_at(2.0), settings)
    measured = img[..., 0] < 128
    expected = expected_shadow_mask()
    assert expected.sum() > 15
    # Only pixels whose centres lie within a pixel of the shadow's edge may differ.
    assert (measured != expected).sum() <= 4
    assert img[32, 38, 0] == 255 and img[32, 32, 0] == 255  # lit plane, lit occluder


@pytest.mark.gl
def test_shadow_darkens_the_shaded_pass(renderer):
    back_v, back_f = quad(1.0, 0.0)
    occ_v, occ_f = quad(0.1, 0.2)
    frame = MeshFrame(np.concatenate([back_v, occ_v]), np.concatenate([back_f, occ_f + 4]))
    lit = PreviewSettings(**{**FLAT.__dict__, "light_dir": (1.0, 0.0, 1.0), "shadows": True})
    img = renderer.render(frame, camera_at(2.0), lit)
    mask = expected_shadow_mask()
    # In shadow only ambient: 0.5 * 0.2 = 0.1 -> 25.5; lit: 0.5 * (0.2 + 0.6 cos 45) = 0.312 -> 79.6.
    inner = mask & np.roll(mask, 1, 0) & np.roll(mask, -1, 0) & np.roll(mask, 1, 1) & np.roll(mask, -1, 1)
    assert np.abs(img[inner, 0].astype(float) - 25.5).max() <= 1
    assert abs(float(img[32, 40, 0]) - 79.6) <= 1


@pytest.mark.gl
def test_wireframe_and_landmarks(renderer):
    v, f = quad(5.0, 0.0)
    cam = camera_at(1.0, 90.0)
    plain = renderer.render(MeshFrame(v, f), cam, FLAT)
    wire = renderer.render(MeshFrame(v, f, landmarks=np.array([[-0.5, 0.5, 0.0]])), cam,
                           PreviewSettings(**{**FLAT.__dict__, "wireframe_overlay": True, "landmarks": True}))
    # The shared edge of the two triangles runs from world (-5,-5) to (5,5): the image's anti-diagonal,
    # row k, column W-1-k (rows top first). Edge pixels are darker, pixels off the edge unchanged.
    diag = [min(wire[k, W - 1 - k, 0], wire[k, W - k - 2, 0], wire[k, W - k, 0]) for k in range(2, W - 2)]
    assert max(diag) < 90
    assert wire[10, 10, 0] == plain[10, 10, 0] and wire[50, 50, 0] == plain[50, 50, 0]
    # The landmark at (-0.5, 0.5) projects (fov 90, 1 m) to pixel column 16, row 16: green.
    r, g, b = wire[16, 16].astype(int)
    assert g > 200 and r < 60 and b < 100


PYRENDER_SCRIPT = r"""
import os, sys, json
os.environ["PYOPENGL_PLATFORM"] = "egl"
import numpy as np
np.infty = np.inf  # pyrender 0.1.45 predates numpy 2
import pyrender, trimesh
d = np.load(sys.argv[1])
mesh = trimesh.Trimesh(d["vertices"], d["triangles"], process=False)
scene = pyrender.Scene()
material = pyrender.MetallicRoughnessMaterial(doubleSided=True)  # we draw both sides too
scene.add(pyrender.Mesh.from_trimesh(mesh, material=material, smooth=False))
cam = pyrender.PerspectiveCamera(yfov=float(d["yfov"]), znear=float(d["near"]), zfar=float(d["far"]),
                                 aspectRatio=float(d["aspect"]))
scene.add(cam, pose=d["pose"])
r = pyrender.OffscreenRenderer(int(d["w"]), int(d["h"]))
depth = r.render(scene, flags=pyrender.RenderFlags.DEPTH_ONLY)
np.save(sys.argv[2], depth)
"""


@pytest.mark.gl
def test_depth_matches_pyrender(renderer, builtin_model, tmp_path):
    """The same head and camera through pyrender (its own GL code, in its own process): depth agrees."""
    pytest.importorskip("pyrender")
    from render.camera import framing_camera

    w, h = 160, 120
    cam = framing_camera(builtin_model.template, yaw_deg=35, pitch_deg=10, width_px=w, height_px=h)
    rgb = renderer.render(MeshFrame(builtin_model.template, builtin_model.triangles), cam,
                          PreviewSettings(samples=1, shadows=False), read_depth=True)
    # pyrender culls back faces (the head's inside, seen through the mouth and eye slits); our shader
    # paints them one fixed colour, so those pixels are left out of the comparison.
    back_facing = np.all(np.abs(rgb.astype(int) - [20, 8, 8]) <= 1, axis=2)
    assert 0 < back_facing.sum() < 0.02 * w * h
    ours = np.where(back_facing, np.inf, renderer.last_depth)
    np.savez(tmp_path / "in.npz", vertices=builtin_model.template, triangles=builtin_model.triangles,
             yfov=math.radians(cam.fov_y_deg), near=cam.near_m, far=cam.far_m, aspect=w / h,
             pose=np.linalg.inv(cam.view), w=w, h=h)
    script = tmp_path / "ref.py"
    script.write_text(PYRENDER_SCRIPT)
    subprocess.run([sys.executable, str(script), str(tmp_path / "in.npz"), str(tmp_path / "ref.npy")],
                   check=True, env={**os.environ, "PYOPENGL_PLATFORM": "egl"}, timeout=120)
    ref = np.load(tmp_path / "ref.npy")
    ref = np.where(ref > 0, ref, np.inf)
    # pyrender reads depth from a 4x multisampled buffer resolved with GL_NEAREST: each pixel holds one
    # sample, up to half a pixel from the centre where we sample. So a pixel of pyrender's must lie within
    # the range of our depths over its 3x3 neighbourhood, and silhouettes may differ only at our edge.
    mask = np.isfinite(ours)
    mwin = np.lib.stride_tricks.sliding_window_view(np.pad(mask, 1, mode="edge"), (3, 3))
    at_edge = mwin.any(axis=(2, 3)) & ~mwin.all(axis=(2, 3))
    differs = mask != np.isfinite(ref)
    # Sub-pixel gaps (the closed lips part by 0.8 mm) let an off-centre sample through to a culled back
    # face: a handful of pixels, never more than 0.1% of the image.
    assert (differs & ~at_edge).sum() <= 0.001 * w * h
    win = np.lib.stride_tricks.sliding_window_view(np.pad(ours, 1, mode="edge"), (3, 3))
    lo, hi = win.min(axis=(2, 3)), win.max(axis=(2, 3))
    interior = mask & np.isfinite(ref) & ~at_edge
    assert interior.sum() > 0.15 * w * h
    inside = (ref[interior] >= lo[interior] - 1e-4) & (ref[interior] <= hi[interior] + 1e-4)
    assert inside.mean() > 0.995, f"{(~inside).sum()} of {interior.sum()} pixels outside the neighbourhood range"
    assert np.median(np.abs(ours[interior] - ref[interior])) < 2e-3


@pytest.mark.gl
def test_two_contexts_in_one_process(gl):
    """A second context made current in between (another command, a window) must not disturb the first."""
    from render.gl.context import GLContext

    v, f = quad(5.0, 0.0)
    first = PreviewRenderer(gl)
    expected = first.render(MeshFrame(v, f), camera_at(1.0, 90.0), FLAT)
    other = GLContext.headless()  # becomes current
    small = Camera(look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3)), 90.0, 32, 24)
    PreviewRenderer(other).render(MeshFrame(v[::-1].copy(), f), small, PreviewSettings(pass_name="normals"))
    again = first.render(MeshFrame(v, f), camera_at(1.0, 90.0), FLAT)
    assert np.array_equal(again, expected) and abs(int(again[8, 8, 0]) - 102) <= 1
    fresh = PreviewRenderer(gl).render(MeshFrame(v, f), camera_at(1.0, 90.0), FLAT)  # objects made now too
    assert np.array_equal(fresh, expected)
    other.release()
