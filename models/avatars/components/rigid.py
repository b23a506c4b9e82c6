"""The best rigid motion between two point sets: how models that read a frame in the head's own frame (NerFACE,
the primitives' view direction) get the head's pose from the posed mesh, whatever the head model's joints."""

from __future__ import annotations

import torch


def kabsch(source: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The rotation R and translation t minimising |R source + t - target| over (V,3) point sets."""
    cs, ct = source.mean(0), target.mean(0)
    u, _, vh = torch.linalg.svd((source - cs).T.double() @ (target - ct).double())
    d = torch.sign(torch.linalg.det(vh.T @ u.T))
    r = (vh.T @ torch.diag(torch.tensor([1.0, 1.0, float(d)], dtype=torch.float64, device=vh.device)) @ u.T).float()
    return r, ct - r @ cs
