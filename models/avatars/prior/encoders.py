"""The universal prior's two encoders (Cao et al. 2022, Section 3.1, Eq. 1-2 and Fig. 3).

- The identity encoder E_id: a person's neutral texture and geometry maps (3,S,S each), each through a 1x1
  convolution to 8 channels and strided 4x4 convolutions with LeakyReLU that halve the size and double the
  channels; at every size the decoder has a bias map of, the two branches' features are joined and a 1x1
  convolution writes that bias map (a U-Net's skips from the conditioning maps into the decoder). Its heads start
  at zero: an untrained prior decodes as its shared decoder does.
- The expression encoder E_exp, variational: the frame's neutral-differenced texture and geometry (6,S,S), strided
  convolutions down to 4x4, the mean and log-variance of a 4x4x16 spatial code (fully convolutional, so each
  latent cell acts where it sits on the head)."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn


def _down(c_in: int, c_out: int) -> nn.Conv2d:
    return nn.Conv2d(c_in, c_out, 4, stride=2, padding=1)


class IdentityEncoder(nn.Module):
    def __init__(self, size: int, bias_shapes: list[tuple[int, int, int]], width: int = 8, max_width: int = 64):
        super().__init__()
        assert size & (size - 1) == 0 and size >= 8, size
        self.size = size
        levels = int(math.log2(size // 8))  # S, S/2, ..., 8
        chans = [min(max_width, width * 2 ** k) for k in range(levels + 1)]
        self.tex_in, self.geo_in = nn.Conv2d(3, width, 1), nn.Conv2d(3, width, 1)
        self.tex_down = nn.ModuleList(_down(chans[k], chans[k + 1]) for k in range(levels))
        self.geo_down = nn.ModuleList(_down(chans[k], chans[k + 1]) for k in range(levels))
        sizes = [size // 2 ** k for k in range(levels + 1)]
        self.sources = []
        self.heads = nn.ModuleList()
        for c, h, w in bias_shapes:
            assert h == w and h in sizes, f"no encoder level of size {h} (levels {sizes})"
            k = sizes.index(h)
            self.sources.append(k)
            head = nn.Conv2d(2 * chans[k], c, 1)
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)
            self.heads.append(head)

    def forward(self, texture: torch.Tensor, geometry: torch.Tensor) -> list[torch.Tensor]:
        """texture, geometry (1,3,S,S) -> one bias map (1,C,H,W) for each of the decoder's bias_shapes."""
        t, g = F.leaky_relu(self.tex_in(texture), 0.2), F.leaky_relu(self.geo_in(geometry), 0.2)
        feats = [torch.cat([t, g], 1)]
        for dt, dg in zip(self.tex_down, self.geo_down, strict=True):
            t, g = F.leaky_relu(dt(t), 0.2), F.leaky_relu(dg(g), 0.2)
            feats.append(torch.cat([t, g], 1))
        return [head(feats[k]) for k, head in zip(self.sources, self.heads, strict=True)]


class ExpressionEncoder(nn.Module):
    def __init__(self, size: int, latent: int = 16, width: int = 16, max_width: int = 64):
        super().__init__()
        assert size & (size - 1) == 0 and size >= 8, size
        levels = int(math.log2(size // 4))
        chans = [min(max_width, width * 2 ** k) for k in range(levels + 1)]
        self.inp = nn.Conv2d(6, width, 1)
        self.down = nn.ModuleList(_down(chans[k], chans[k + 1]) for k in range(levels))
        self.mean = nn.Conv2d(chans[-1], latent, 1)
        self.log_var = nn.Conv2d(chans[-1], latent, 1)
        nn.init.zeros_(self.log_var.weight)
        nn.init.constant_(self.log_var.bias, -4.0)  # start nearly deterministic

    def forward(self, delta_texture: torch.Tensor, delta_geometry: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """(1,3,S,S) each -> mean and log-variance (1,latent,4,4) of the expression code."""
        h = F.leaky_relu(self.inp(torch.cat([delta_texture, delta_geometry], 1)), 0.2)
        for d in self.down:
            h = F.leaky_relu(d(h), 0.2)
        return self.mean(h), self.log_var(h).clamp(-12.0, 6.0)


def kl_divergence(mean: torch.Tensor, log_var: torch.Tensor) -> torch.Tensor:
    """KL(N(mean, exp(log_var)) || N(0, 1)), summed over the code, averaged over the batch (the VAE's term).

    >>> float(kl_divergence(torch.zeros(1, 2), torch.zeros(1, 2)))
    0.0
    >>> round(float(kl_divergence(torch.ones(1, 1), torch.zeros(1, 1))), 3)  # (1 + 1 - 1 - 0) / 2
    0.5
    """
    return 0.5 * (mean.square() + log_var.exp() - 1.0 - log_var).flatten(1).sum(1).mean()
