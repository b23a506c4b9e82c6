"""Training losses (CoDyNeRF, Eq. 9-14), each a pure function of tensors."""

from __future__ import annotations

import torch


def photometric(rgb: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared error over rays and channels, (R,3) each."""
    return ((rgb - target) ** 2).mean()


def normals_facing_camera(weights: torch.Tensor, normals: torch.Tensor, ray_dirs: torch.Tensor) -> torch.Tensor:
    """Eq. 10: sum_i w_i max(0, n_i . d)^2 per ray, averaged over rays. d points away from the camera, so a
    normal that faces away from it is penalised. weights (R,S), normals (R,S,3), ray_dirs (R,3).

    The weights only say where to look: they are detached, or the cheapest way to lower the term is to
    remove the density (with random early normals, training collapsed to an empty field within 300 steps)."""
    facing = (normals * ray_dirs[:, None]).sum(-1).clamp_min(0.0)
    return (weights.detach() * facing**2).sum(-1).mean()


def top_k_normal_consistency(weights: torch.Tensor, normals: torch.Tensor, grad_normals: torch.Tensor,
                             k: int = 4) -> torch.Tensor:
    """Eq. 13: sum over the k highest-weighted samples of each ray of w_i |N(x_i) - Grad_n(x_i)|, averaged
    over rays. Only samples near the surface tie the two normals together."""
    k = min(k, weights.shape[-1])
    w, idx = weights.detach().topk(k, dim=-1)  # where to look, not something to shrink (see Eq. 10's note)
    gather = lambda t: t.gather(1, idx[..., None].expand(-1, -1, 3))
    return (w * (gather(normals) - gather(grad_normals)).norm(dim=-1)).sum(-1).mean()


def blocked_light(weights: torch.Tensor, light: torch.Tensor) -> torch.Tensor:
    """sum_i w_i (1 - F_i) per ray, averaged over rays: the share of the colour the shadow factor F (R,S)
    takes away where the surface is, weights (R,S) detached (where to look, as in Eq. 10)."""
    return (weights.detach() * (1.0 - light)).sum(-1).mean()


def mesh_normal_consistency(pred: torch.Tensor, mesh: torch.Tensor) -> torch.Tensor:
    """Eq. 9: mean over vertices of |N(v) - Mesh_n(v)|, (V,3) each."""
    return (pred - mesh).norm(dim=-1).mean()


def cauchy_sparsity(sigma: torch.Tensor, c: float = 1.0) -> torch.Tensor:
    """Eq. 14: mean of log(1 + sigma^2 / c): pushes densities away from the surface towards zero."""
    return torch.log1p(sigma**2 / c).mean()


def code_l2(*codes: torch.Tensor) -> torch.Tensor:
    return sum((c**2).sum(-1).mean() for c in codes)
