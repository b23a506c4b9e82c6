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

    def forward(self, x: torch.Tensor, code: torch.Tensor | None = None, code_at: int | None = None) -> torch.Tensor:
        """x: (P, d_in) inputs; or, with `code`, the inputs other than the code's C columns, which sit at
        column `code_at` of the input (default: last). A code of shape (1, C), shared by every point, is
        folded into the first layer's bias: no (P, C) copy and no concatenation."""
        if code is None:
            return self.net(x)
        at = x.shape[1] if code_at is None else code_at
        if code.shape[0] != 1 or len(x) == 1:
            return self.net(torch.cat([x[:, :at], code.expand(len(x), -1), x[:, at:]], -1))
        first = self.net[0]
        C = code.shape[1]
        bias = first.bias + first.weight[:, at:at + C] @ code[0]
        weight = torch.cat([first.weight[:, :at], first.weight[:, at + C:]], 1)
        return self.net[1:](torch.nn.functional.linear(x, weight, bias))
