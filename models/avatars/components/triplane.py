"""Features on three axis-aligned planes over a box (the tri-plane of EG3D and TensoRF's plane factors): a point's
features are the bilinear lookups of its projections onto the xy, xz and yz planes, side by side. A lookup costs
three bilinear reads, whatever the detail stored: the cheap way to give a small MLP sharp detail on a CPU."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

PLANE_AXES = ((0, 1), (0, 2), (1, 2))
"""The coordinates each plane keeps: xy, xz, yz."""


def triplane_lookup(planes: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """Bilinear features (P, 3C) of points u (P,3) in box coordinates [-1, 1] (outside: the border's) from
    planes (3, C, R, R); plane k's rows follow the second of its axes, its columns the first (grid_sample's x, y).

    >>> planes = torch.arange(4.0).reshape(1, 1, 2, 2).repeat(3, 1, 1, 1)  # [[0, 1], [2, 3]] on every plane
    >>> triplane_lookup(planes, torch.tensor([[0.0, 0.0, 1.0]]))  # centre of xy: 1.5; xz at (0,1): 2.5; yz: 2.5
    tensor([[1.5000, 2.5000, 2.5000]])
    """
    assert planes.dim() == 4 and planes.shape[0] == 3 and u.dim() == 2 and u.shape[1] == 3, (planes.shape, u.shape)
    grid = torch.stack([u[:, list(axes)] for axes in PLANE_AXES])[:, None]  # (3,1,P,2)
    f = F.grid_sample(planes, grid, mode="bilinear", padding_mode="border", align_corners=True)  # (3,C,1,P)
    return f[:, :, 0].permute(2, 0, 1).reshape(len(u), -1)


class TriPlane(nn.Module):
    """Learnt tri-plane features over the box [box_min, box_max] (metres), `resolution` texels a side."""

    def __init__(self, box_min: torch.Tensor, box_max: torch.Tensor, resolution: int, features: int,
                 init_scale: float = 0.1):
        super().__init__()
        self.register_buffer("box_min", torch.as_tensor(box_min, dtype=torch.float32).clone())
        self.register_buffer("box_max", torch.as_tensor(box_max, dtype=torch.float32).clone())
        self.planes = nn.Parameter(init_scale * torch.randn(3, features, resolution, resolution))

    @property
    def out_features(self) -> int:
        return 3 * self.planes.shape[1]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(P, 3C) features at points x (P,3), metres."""
        u = 2.0 * (x - self.box_min) / (self.box_max - self.box_min) - 1.0
        return triplane_lookup(self.planes, u)
