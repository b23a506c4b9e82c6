"""The guide mesh's shadow map looked up at points: against an independent ray-plate intersection, at the
bias, and for points that are not finite."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from render.gl.raster import Rasterizer
from render.gl.shadow import draw_light_depth
from render.shadow_map import BIAS_M, SOFT_M

pytestmark = pytest.mark.gl

# A 20 cm square plate at y = 0 and a small box 8 cm above it: the shapes whose shadows we can work out by hand.
PLATE = np.array([[-0.1, 0, -0.1], [0.1, 0, -0.1], [0.1, 0, 0.1], [-0.1, 0, 0.1]], np.float32)
PLATE_TRIS = np.array([[0, 1, 2], [0, 2, 3]])


def blocked_by_plate(x: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Whether the ray from each point towards the light crosses the plate (independent of GL)."""
    t = -x[:, 1] / light[1]
    hit = x + t[:, None] * light
    return (t > 0) & (np.abs(hit[:, 0]) < 0.1) & (np.abs(hit[:, 2]) < 0.1)


@pytest.mark.parametrize("light", [(0.0, 1.0, 0.0), (0.4, 0.8, 0.3)])
def test_plate_shadow_matches_ray_casting(gl, light):
    light = np.asarray(light) / np.linalg.norm(light)
    ml = draw_light_depth(Rasterizer(gl), PLATE, PLATE_TRIS, light)
    rng = np.random.default_rng(0)
    x = rng.uniform([-0.15, -0.1, -0.15], [0.15, -0.01, 0.15], (4000, 3)).astype(np.float32)  # below the plate
    vis = ml.visibility(torch.as_tensor(x)).numpy()
    truth = blocked_by_plate(x.astype(np.float64), light)
    # Away from the shadow's edge (more than 2 texels of the map), the map agrees with ray casting exactly.
    texel = 2 * 0.1 * np.sqrt(2) * 1.05 / 256
    t = -x[:, 1] / light[1]
    hit = x + t[:, None] * light
    edge = np.minimum(np.abs(np.abs(hit[:, 0]) - 0.1), np.abs(np.abs(hit[:, 2]) - 0.1)) < 2 * texel
    assert (vis[truth & ~edge] < 1e-6).all() and (vis[~truth & ~edge] > 1 - 1e-6).all()
    assert truth.sum() > 500 and (~truth).sum() > 500  # both cases well represented
    assert ((vis >= 0) & (vis <= 1)).all()


def test_bias_keeps_the_surface_lit(gl):
    """Points on the plate and just under it are lit; deeper than the bias plus the soft band, blocked."""
    ml = draw_light_depth(Rasterizer(gl), PLATE, PLATE_TRIS, (0.0, 1.0, 0.0))
    depths = np.array([0.0, BIAS_M * 0.5, BIAS_M + SOFT_M, 0.02])
    x = torch.as_tensor(np.stack([np.full(4, 0.013), -depths, np.full(4, -0.021)], 1), dtype=torch.float32)
    vis = ml.visibility(x).numpy()
    np.testing.assert_allclose(vis, [1.0, 1.0, 0.0, 0.0], atol=1e-5)
    # in the soft band, halfway: 0.5
    mid = ml.visibility(torch.tensor([[0.013, -BIAS_M, -0.021]])).item()
    assert mid == pytest.approx(0.5, abs=1e-3)


def test_points_off_the_map_or_not_finite_are_lit(gl):
    ml = draw_light_depth(Rasterizer(gl), PLATE, PLATE_TRIS, (0.0, 1.0, 0.0))
    x = torch.tensor([[5.0, -0.05, 0.0], [float("nan"), -0.05, 0.0], [float("inf"), 0, 0], [0, -1e30, 0]])
    vis = ml.visibility(x)
    assert torch.isfinite(vis).all() and (vis[:3] > 1 - 1e-6).all() and 0 <= vis[3] <= 1
