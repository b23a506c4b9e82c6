"""The surface's normals (render/normals.py) against analytic spheres and a synthetic capture's true normals."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from render.camera import Camera, look_at
from render.normals import MESH_REACH_M, depth_normal_image, mesh_normal_image, surface_normal_image
from render.rays import pixel_rays

RADIUS, CENTRE = 0.1, np.array([0.0, 0.0, -0.5])


def sphere_view(size: int = 64) -> tuple[Camera, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A camera at the origin looking down -z at a sphere of 10 cm 0.5 m away: its origin, unit rays, the distance
    along each to the sphere (inf where a ray misses) and the sphere's true normals there."""
    cam = Camera(look_at(np.zeros(3), CENTRE), 30.0, size, size)
    origin, d = pixel_rays(cam)
    oc = origin - CENTRE  # |o + t d - c|^2 = r^2: t^2 + 2 t (d.oc) + |oc|^2 - r^2 = 0
    b = d @ oc
    disc = b * b - (oc @ oc - RADIUS**2)
    t = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    points = origin + np.where(np.isfinite(t), t, 0)[..., None] * d
    truth = (points - CENTRE) / RADIUS
    return cam, origin, d, t, truth


def angles(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip((a[mask] * b[mask]).sum(-1), -1, 1)))


def test_depth_normals_of_a_sphere():
    """The sphere's own depth gives its normals: within 1 degree over the disc's inside (central differences of a
    smoothed sphere: the blur flattens it a little; every pixel within 8 px of the middle), none outside it."""
    _, origin, d, t, truth = sphere_view()
    n = depth_normal_image(origin, d, t, sigma_px=1.0)
    inside = np.isfinite(t)
    rows, cols = np.indices(t.shape)
    middle = np.hypot(rows - 31.5, cols - 31.5) < 8
    assert np.median(angles(n, truth, inside)) < 1.0
    assert angles(n, truth, middle).max() < 1.0
    assert np.abs(n[~inside]).max() == 0
    np.testing.assert_allclose(np.linalg.norm(n[inside], axis=-1), 1.0, atol=1e-5)


def test_depth_normals_take_no_difference_across_a_jump():
    """A plate 10 cm behind a step: the pixels on either side of the step keep the plane's normal (one-sided
    differences on their own surface), where a difference across it would tilt them by tens of degrees."""
    cam = Camera(look_at(np.zeros(3), np.array([0.0, 0, -1])), 30.0, 32, 32)
    origin, d = pixel_rays(cam)
    z = np.where(np.arange(32)[None, :] < 16, 1.0, 1.1) * np.ones((32, 1))
    for sigma in (0.0, 2.0):  # 2 px: the smoothing the renders use at 256 px (a blur of the points tilted 46 deg)
        n = depth_normal_image(origin, d, z / -d[..., 2], sigma_px=sigma)
        assert angles(n, np.broadcast_to([0.0, 0, 1], n.shape), np.ones((32, 32), bool)).max() < 1e-3, sigma


def test_blend_takes_the_mesh_behind_it_and_the_depth_well_in_front():
    """Hand-worked weights: the render's surface 1 cm in front of the mesh takes the mesh's normal with
    exp(-1) = 0.368; at or behind the mesh the mesh's alone; 3 cm in front exp(-9) = 1.2e-4."""
    up, out = np.array([0.0, 1, 0]), np.array([0.0, 0, 1])
    t_mesh = np.full((1, 4), 1.0)
    t = np.array([[1.0 - MESH_REACH_M, 1.0, 1.02, 1.0 - 3 * MESH_REACH_M]])
    n = surface_normal_image(np.broadcast_to(out, (1, 4, 3)), t, np.broadcast_to(up, (1, 4, 3)), t_mesh)
    w = np.exp(-1.0)
    expected = (w * up + (1 - w) * out) / np.linalg.norm(w * up + (1 - w) * out)
    np.testing.assert_allclose(n[0, 0], expected, atol=1e-6)
    np.testing.assert_allclose(n[0, 1], up, atol=1e-6)
    np.testing.assert_allclose(n[0, 2], up, atol=1e-6)
    assert n[0, 3] @ out > 0.9999


@pytest.mark.gl
def test_mesh_normals_of_a_rasterized_sphere(gl):
    """An icosphere through the real GL rasterizer: interpolated vertex normals within 2 degrees of the sphere's
    (the icosphere's own facets, 2562 vertices)."""
    from render.gl.raster import Rasterizer

    cam, _, _, t, truth = sphere_view(96)
    ico = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    verts = np.asarray(ico.vertices) + CENTRE
    raster = Rasterizer(gl).rasterize(verts.astype(np.float32), np.asarray(ico.faces), cam)
    n = mesh_normal_image(raster, verts, np.asarray(ico.faces))
    both = raster.hit & np.isfinite(t)
    assert both.sum() > 2000
    assert angles(n, truth, both).max() < 2.0
    assert np.abs(n[~raster.hit]).max() == 0
