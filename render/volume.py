"""Volume rendering along rays as pure functions of tensors (NeRF; CoDyNeRF's Eq. 1).

Shapes: R rays, S samples per ray. Samples are intervals [t_start, t_end) along each ray, in metres.
Every function is finite, with finite gradients, for densities from 0 to 1e6 and intervals of any length.
"""

from __future__ import annotations

import torch


def alpha_from_density(
    sigmas: torch.Tensor,  # (R,S) density, 1/m, >= 0
    deltas: torch.Tensor,  # (R,S) interval lengths, m
) -> torch.Tensor:
    """alpha_i = 1 - exp(-sigma_i delta_i), computed as -expm1 so small products keep their precision.

    >>> alpha_from_density(torch.tensor([[0.0, 1.0, 1e6]]), torch.tensor([[0.5, 0.5, 0.5]]))
    tensor([[0.0000, 0.3935, 1.0000]])
    """
    return -torch.expm1(-(sigmas * deltas))


def transmittance_from_density(
    sigmas: torch.Tensor,  # (R,S)
    deltas: torch.Tensor,  # (R,S)
) -> torch.Tensor:
    """T_i = exp(-sum_{j<i} sigma_j delta_j): the light that reaches sample i unabsorbed, (R,S)."""
    tau = sigmas * deltas
    exclusive = torch.cumsum(tau, dim=-1) - tau
    return torch.exp(-exclusive)


def weights_from_density(
    sigmas: torch.Tensor,  # (R,S)
    deltas: torch.Tensor,  # (R,S)
) -> tuple[torch.Tensor, torch.Tensor]:
    """w_i = T_i alpha_i (Eq. 1), and the transmittance left after the last sample, (R,S) and (R,).

    >>> w, rest = weights_from_density(torch.tensor([[1.0, 1.0]]), torch.tensor([[0.6931472, 0.6931472]]))
    >>> w, rest  # alpha = 1/2 each: weights 1/2 and 1/4, a quarter of the light passes
    (tensor([[0.5000, 0.2500]]), tensor([0.2500]))
    """
    assert sigmas.shape == deltas.shape, f"sigmas {sigmas.shape} and deltas {deltas.shape} differ"
    T = transmittance_from_density(sigmas, deltas)
    alpha = alpha_from_density(sigmas, deltas)
    weights = T * alpha
    remaining = T[..., -1] * (1 - alpha[..., -1]) if sigmas.shape[-1] else torch.ones(sigmas.shape[:-1])
    return weights, remaining


def composite(
    weights: torch.Tensor,  # (R,S)
    values: torch.Tensor,  # (R,S,C)
    remaining: torch.Tensor | None = None,  # (R,) transmittance past the last sample
    background: torch.Tensor | None = None,  # (C,) or (R,C)
) -> torch.Tensor:
    """sum_i w_i v_i, plus the background seen through what is left: (R,C)."""
    out = (weights[..., None] * values).sum(dim=-2)
    if background is not None:
        assert remaining is not None, "compositing a background needs the remaining transmittance"
        out = out + remaining[..., None] * background
    return out


def expected_depth(weights: torch.Tensor, t_mid: torch.Tensor) -> torch.Tensor:
    """sum_i w_i t_i / sum_i w_i, (R,); rays with no opacity get the far end of their samples."""
    opacity = weights.sum(-1)
    depth = (weights * t_mid).sum(-1) / opacity.clamp_min(1e-10)
    return torch.where(opacity > 1e-10, depth, t_mid[..., -1] if t_mid.shape[-1] else torch.zeros_like(opacity))


def ray_aabb_intersect(
    origins: torch.Tensor,  # (R,3)
    directions: torch.Tensor,  # (R,3), need not be unit
    box_min: torch.Tensor,  # (3,)
    box_max: torch.Tensor,  # (3,)
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Slab test: t_near, t_far (R,) with t_near >= 0, and hit (R,) for rays that pass through the box.

    Direction components of zero (rays parallel to a face) are handled without dividing by zero; a ray
    that grazes a face or edge counts as a hit of zero length.
    """
    big = torch.finfo(directions.dtype).max / 4
    parallel = directions.abs() < 1e-12  # such a ray never crosses this pair of faces
    safe = torch.where(parallel, torch.ones_like(directions), directions)
    t0 = (box_min - origins) / safe
    t1 = (box_max - origins) / safe
    lo, hi = torch.minimum(t0, t1), torch.maximum(t0, t1)
    inside = (origins >= box_min) & (origins <= box_max)
    far = torch.full_like(lo, big)
    lo = torch.where(parallel, torch.where(inside, -far, far), lo)
    hi = torch.where(parallel, torch.where(inside, far, -far), hi)
    t_near = lo.amax(-1).clamp_min(0.0)
    t_far = hi.amin(-1)
    hit = t_far >= t_near
    return torch.where(hit, t_near, torch.zeros_like(t_near)), torch.where(hit, t_far, torch.zeros_like(t_far)), hit


def sample_pdf(
    bins: torch.Tensor,  # (R,S+1) interval edges along each ray
    weights: torch.Tensor,  # (R,S) non-negative
    n_samples: int,
    generator: torch.Generator | None = None,  # None: evenly spaced quantiles (deterministic)
    eps: float = 1e-5,
) -> torch.Tensor:
    """Inverse-transform samples of the piecewise-constant pdf that `weights` put on `bins` (R,n_samples),
    sorted. A ray whose weights are all zero is sampled uniformly over its bins."""
    R, S = weights.shape
    assert bins.shape == (R, S + 1), f"bins must be (R,S+1)=({R},{S + 1}), got {tuple(bins.shape)}"
    w = weights + eps  # no empty pdf, no division by zero
    pdf = w / w.sum(-1, keepdim=True)
    cdf = torch.cat([torch.zeros_like(pdf[..., :1]), torch.cumsum(pdf, -1)], -1).clamp(max=1.0)  # (R,S+1)
    if generator is None:
        u = torch.linspace(0.5 / n_samples, 1 - 0.5 / n_samples, n_samples, dtype=bins.dtype, device=bins.device)
        u = u.expand(R, n_samples).contiguous()
    else:
        u = torch.rand(R, n_samples, generator=generator, dtype=bins.dtype).to(bins.device)
        u, _ = torch.sort(u, dim=-1)
    idx = torch.searchsorted(cdf.detach().contiguous(), u, right=True).clamp(1, S)
    cdf_lo, cdf_hi = cdf.gather(-1, idx - 1), cdf.gather(-1, idx)
    bin_lo, bin_hi = bins.gather(-1, idx - 1), bins.gather(-1, idx)
    span = cdf_hi - cdf_lo
    frac = (u - cdf_lo) / torch.where(span > 1e-12, span, torch.ones_like(span))
    return bin_lo + frac.clamp(0, 1) * (bin_hi - bin_lo)
