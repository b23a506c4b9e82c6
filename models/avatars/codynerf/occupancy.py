"""An occupancy grid in canonical space (docs/models.md): which cells of the canonical head's box hold any density.
Display rendering skips the density and appearance networks for samples whose canonical position (after the
deformation, Eq. 2) falls in an empty cell. (Looking up before the learned residual deformation is cheaper
but wrong for posed frames: the prior fades with distance from the mesh, so the prior-deformed point is not
canonical, and test renders lost 9-11 dB.)

The grid is built from the trained density itself, so it is only as conservative as its threshold and its
dilation; tests bound the image error it causes against rendering without it.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import nn


class OccupancyGrid(nn.Module):
    """A boolean grid over an axis-aligned box; saved with the avatar (buffers)."""

    def __init__(self, box_min: torch.Tensor, box_max: torch.Tensor, resolution: int = 48):
        super().__init__()
        self.resolution = resolution
        self.register_buffer("box_min", box_min.float().clone())
        self.register_buffer("box_max", box_max.float().clone())
        self.register_buffer("occupied", torch.ones((resolution,) * 3, dtype=torch.bool))
        self.register_buffer("built", torch.tensor(False))

    def cell_of(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Integer cells (P,3) of points and whether each lies inside the box."""
        u = (points - self.box_min) / (self.box_max - self.box_min)
        inside = ((u >= 0) & (u < 1)).all(-1)
        cell = (u.clamp(0, 1 - 1e-6) * self.resolution).long()
        return cell, inside

    def lookup(self, points: torch.Tensor) -> torch.Tensor:
        """(P,) True where a point may hold density: in an occupied cell, outside the box (not known), or
        anywhere while the grid is not built."""
        if not bool(self.built):
            return torch.ones(len(points), dtype=torch.bool, device=points.device)
        finite = torch.isfinite(points).all(-1)
        cell, inside = self.cell_of(torch.where(finite[:, None], points, self.box_min))
        return ~(inside & finite) | self.occupied[cell[:, 0], cell[:, 1], cell[:, 2]]

    @torch.no_grad()
    def build(self, density: Callable[[torch.Tensor], torch.Tensor], threshold: float, dilation: int = 2,
              points_per_cell: int = 4, generator: torch.Generator | None = None, chunk: int = 65536) -> float:
        """Mark cells where `density` (of (P,3) canonical points) exceeds `threshold` at any of a few random
        points in the cell, then grow the occupied set by `dilation` cells. Returns the occupied fraction."""
        n = self.resolution
        idx = torch.stack(torch.meshgrid(*(torch.arange(n),) * 3, indexing="ij"), -1).reshape(-1, 3)
        size = (self.box_max - self.box_min) / n
        peak = torch.zeros(len(idx))
        for _ in range(points_per_cell):
            jitter = torch.rand(len(idx), 3, generator=generator)
            pts = self.box_min + (idx + jitter).to(size.device) * size
            values = torch.cat([density(pts[a:a + chunk]).float().cpu() for a in range(0, len(pts), chunk)])
            peak = torch.maximum(peak, values)
        occ = (peak > threshold).reshape(1, 1, n, n, n).float()
        if dilation > 0:
            occ = F.max_pool3d(occ, 2 * dilation + 1, stride=1, padding=dilation)
        self.occupied.copy_((occ[0, 0] > 0).to(self.occupied.device))
        self.built.fill_(True)
        return float(self.occupied.float().mean())
