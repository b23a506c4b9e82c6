"""A plain MLP: the building block of every field."""

from __future__ import annotations

import torch
from torch import nn


class MLP(nn.Module):
    """depth hidden layers of `width` with ReLU; the last layer can start at zero (an identity residual)."""

    def __init__(self, d_in: int, d_out: int, width: int, depth: int, zero_last: bool = False):
        super().__init__()
        layers: list[nn.Module] = []
        d = d_in
        for _ in range(depth):
            layers += [nn.Linear(d, width), nn.ReLU(inplace=True)]
            d = width
        last = nn.Linear(d, d_out)
        if zero_last:
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)
        self.net = nn.Sequential(*layers, last)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)
