"""Frequency (positional) encoding gamma of NeRF, as a pure function."""

from __future__ import annotations

import math

import torch


def frequency_encoding(x: torch.Tensor, n_frequencies: int, scale: float = 1.0) -> torch.Tensor:
    """gamma(x) = (x, sin(2^k pi x / scale), cos(2^k pi x / scale) for k < n): (..., D) -> (..., D (1 + 2n)).

    `scale` is the length (metres) of the longest period's half: positions in [-scale, scale] are encoded
    without aliasing the lowest frequency.

    >>> frequency_encoding(torch.tensor([[0.5]], dtype=torch.float64), 2).round(decimals=6)  # x, sin/cos pi x, 2 pi x
    tensor([[ 0.5000,  1.0000,  0.0000,  0.0000, -1.0000]], dtype=torch.float64)
    """
    if n_frequencies == 0:
        return x
    D = x.shape[-1]
    freqs = (2.0 ** torch.arange(n_frequencies, dtype=x.dtype, device=x.device)) * (math.pi / scale)
    # One buffer, filled in place: x, then per frequency sin of every coordinate, then cos of every coordinate.
    out = x.new_empty(*x.shape[:-1], D * (1 + 2 * n_frequencies))
    out[..., :D] = x
    tail = out[..., D:].unflatten(-1, (n_frequencies, 2, D))
    angles = x[..., None, :] * freqs[:, None]  # (..., n, D)
    tail[..., 0, :] = torch.sin(angles)
    tail[..., 1, :] = torch.cos(angles)
    return out


def encoded_size(dim: int, n_frequencies: int) -> int:
    return dim * (1 + 2 * n_frequencies)
