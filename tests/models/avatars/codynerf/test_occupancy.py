"""The occupancy grid: which cells hold density, checked against a sphere whose cells are known by hand."""

from __future__ import annotations

import itertools

import numpy as np
import torch

from models.avatars.codynerf.occupancy import OccupancyGrid

R = 0.5  # sphere radius, in a [-1, 1]^3 box of 8^3 cells (cells 0.25 wide)


def sphere(x: torch.Tensor) -> torch.Tensor:
    return torch.where(x.norm(dim=-1) < R, 10.0, 0.0)


def cells_by_hand(n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Cells entirely inside the sphere (surely occupied) and entirely outside it (surely empty)."""
    inside = np.zeros((n,) * 3, bool)
    outside = np.zeros((n,) * 3, bool)
    size = 2.0 / n
    for i, j, k in itertools.product(range(n), repeat=3):
        lo = -1 + np.array([i, j, k]) * size
        hi = lo + size
        farthest = np.maximum(np.abs(lo), np.abs(hi))
        nearest = np.where((lo < 0) & (hi > 0), 0.0, np.minimum(np.abs(lo), np.abs(hi)))
        inside[i, j, k] = np.linalg.norm(farthest) < R
        outside[i, j, k] = np.linalg.norm(nearest) > R
    return inside, outside


def test_sphere_cells_match_hand_worked_values():
    grid = OccupancyGrid(torch.full((3,), -1.0), torch.full((3,), 1.0), resolution=8)
    frac = grid.build(sphere, threshold=1.0, dilation=0, points_per_cell=8, generator=torch.Generator().manual_seed(0))
    occ = grid.occupied.numpy()
    inside, outside = cells_by_hand()
    assert inside.sum() == 8 and outside.sum() > 400  # the 8 cells about the centre are entirely inside
    assert occ[inside].all() and not occ[outside].any()
    assert frac == occ.mean()


def test_dilation_grows_by_whole_cells():
    grid = OccupancyGrid(torch.full((3,), -1.0), torch.full((3,), 1.0), resolution=8)
    grid.build(lambda x: torch.where((x > 0).all(-1) & (x < 0.25).all(-1), 1.0, 0.0), threshold=0.5, dilation=1,
               points_per_cell=16, generator=torch.Generator().manual_seed(0))
    # One occupied cell (4,4,4), dilated by one: the 3x3x3 block about it.
    expect = np.zeros((8,) * 3, bool)
    expect[3:6, 3:6, 3:6] = True
    assert (grid.occupied.numpy() == expect).all()


def test_lookup():
    grid = OccupancyGrid(torch.full((3,), -1.0), torch.full((3,), 1.0), resolution=8)
    pts = torch.tensor([[0.0, 0.0, 0.0], [0.9, 0.9, 0.9], [5.0, 0.0, 0.0], [float("nan"), 0.0, 0.0]])
    assert grid.lookup(pts).all()  # not built: everything may hold density
    grid.build(sphere, threshold=1.0, dilation=0, generator=torch.Generator().manual_seed(0))
    # Inside: occupied; a far corner cell: empty; outside the box or not finite: not known, so evaluated.
    assert grid.lookup(pts).tolist() == [True, False, True, True]
