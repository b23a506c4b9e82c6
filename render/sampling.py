"""Where samples go along each ray: a shell around the rasterized surface for rays that see the head
mesh, the head's box for rays that miss it (hair, shoulders, silhouettes), nothing for rays that miss both
(spend samples only where the head is)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from render.volume import ray_aabb_intersect, sample_pdf


@dataclass(frozen=True)
class RaySamples:
    """Intervals along R rays, S per ray, sorted; rays without samples have zero-length intervals."""

    t_starts: torch.Tensor  # (R,S) metres
    t_ends: torch.Tensor  # (R,S)
    valid: torch.Tensor  # (R,) the ray has samples

    @property
    def t_mid(self) -> torch.Tensor:
        return 0.5 * (self.t_starts + self.t_ends)

    @property
    def deltas(self) -> torch.Tensor:
        return self.t_ends - self.t_starts


def stratified(t_near: torch.Tensor, t_far: torch.Tensor, n: int, generator: torch.Generator | None
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """n contiguous intervals covering [t_near, t_far] per ray (R,n); with a generator each interval's
    edges are jittered inside its stratum (training), without it they are even (display)."""
    edges = torch.linspace(0, 1, n + 1, dtype=t_near.dtype, device=t_near.device).expand(len(t_near), n + 1)
    if generator is not None:
        # Drawn on the generator's device (the CPU: its state is saved with checkpoints), used on the rays'.
        jitter = (torch.rand(len(t_near), n - 1, generator=generator, dtype=t_near.dtype).to(t_near.device) - 0.5) / n
        edges = torch.cat([edges[:, :1], edges[:, 1:-1] + jitter, edges[:, -1:]], 1)
    t = t_near[:, None] + edges * (t_far - t_near)[:, None]
    return t[:, :-1], t[:, 1:]


def shell_or_box_samples(
    origins: torch.Tensor,  # (R,3)
    directions: torch.Tensor,  # (R,3) unit
    surface_t: torch.Tensor,  # (R,) distance along the ray to the rasterized surface, inf on a miss
    box_min: torch.Tensor,  # (3,)
    box_max: torch.Tensor,  # (3,)
    n_samples: int,
    shell_m: float = 0.02,
    generator: torch.Generator | None = None,
) -> RaySamples:
    """Rays that see the mesh sample [t - shell, t + shell] about the surface (clipped to the box); others
    sample their whole segment inside the box; rays that miss the box get no samples."""
    t_box_near, t_box_far, in_box = ray_aabb_intersect(origins, directions, box_min, box_max)
    sees_mesh = torch.isfinite(surface_t)
    s_t = torch.where(sees_mesh, surface_t, torch.zeros_like(surface_t))
    near = torch.where(sees_mesh, torch.maximum(s_t - shell_m, t_box_near), t_box_near)
    far = torch.where(sees_mesh, torch.minimum(s_t + shell_m, t_box_far), t_box_far)
    valid = (in_box | sees_mesh) & (far > near)
    near = torch.where(valid, near, torch.zeros_like(near))
    far = torch.where(valid, far, torch.zeros_like(far))
    t0, t1 = stratified(near, far, n_samples, generator)
    return RaySamples(t0, t1, valid)


def fine_samples(samples: RaySamples, weights: torch.Tensor, n: int, generator: torch.Generator | None = None
                 ) -> RaySamples:
    """The first pass's samples plus n drawn where its weights (R,S) lie (inverse-transform sampling), as
    intervals about the sorted sample points, within the first pass's span."""
    edges = torch.cat([samples.t_starts, samples.t_ends[:, -1:]], 1)
    t_all = torch.sort(torch.cat([samples.t_mid, sample_pdf(edges, weights, n, generator)], 1), 1).values
    mids = 0.5 * (t_all[:, 1:] + t_all[:, :-1])
    return RaySamples(torch.cat([samples.t_starts[:, :1], mids], 1), torch.cat([mids, samples.t_ends[:, -1:]], 1),
                      samples.valid)
