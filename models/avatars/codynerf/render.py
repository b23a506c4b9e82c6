"""Rendering CoDyNeRF's rays in small steps (docs/models.md): where the samples go (the mesh shell, the head's box
beyond the silhouette, the fine pass), the density at them (all of them, or with the early stop), the colour
where they show (all of them, or skipping those below a weight), compositing. Each shortcut sits beside its
exact reference; training always takes the exact path."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import torch

from models.avatars.codynerf.field import FieldOutput
from models.avatars.codynerf.prior import PriorSamples
from render.rays import Rays
from render.sampling import RaySamples, shell_or_box_samples
from render.volume import weights_from_density


@dataclass(frozen=True)
class RaySettings:
    """How one batch of rays is rendered. The shortcuts (stop_below, min_weight, skip_empty) are display's:
    0/False is the exact path."""

    samples: int
    """Samples a ray in the shell about the surface (or across the box for rays that miss the mesh)."""
    shell_m: float
    dense: int = 0
    """The slow reference: ignore the mesh, spread this many samples over the head's box (0: the shell)."""
    fine: int = 0
    """A second pass adds this many samples where the first pass's weights lie (0: one pass)."""
    stop_below: float = 0.0
    """End a ray after its front half once less than this share of the light gets through it."""
    min_weight: float = 0.0
    """Skip the colour of samples that add less than this to their pixel."""
    skip_empty: bool = False
    """Skip the density network where the occupancy grid says the canonical point is empty."""
    create_graph: bool = False
    """Keep the graph of density gradients (training through the normals)."""
    mesh_normals: bool = False
    """The guide mesh's normals stand in for the predicted ones and the density's gradient (neither is computed):
    a tracked video's training before Eq. 13 comes in (LossWeights.mesh_normals_first)."""


def sample_rays(rays: Rays, box_min: torch.Tensor, box_max: torch.Tensor, settings: RaySettings,
                generator: torch.Generator | None = None) -> RaySamples:
    """The first pass's intervals: the shell about the rasterized surface, the box for rays that miss the mesh
    (every ray's box segment for the dense reference)."""
    surface_t = torch.full_like(rays.surface_t, float("inf")) if settings.dense else rays.surface_t
    return shell_or_box_samples(rays.origins, rays.directions, surface_t, box_min, box_max,
                                settings.dense or settings.samples, settings.shell_m, generator)


def sample_points(rays: Rays, samples: RaySamples) -> torch.Tensor:
    """(R*S,3) the samples' midpoints, ray-major."""
    return (rays.origins[:, None] + rays.directions[:, None] * samples.t_mid[..., None]).reshape(-1, 3)


@dataclass
class Densities:
    """The field where it was evaluated: at N of the R*S samples (elsewhere the density is exactly 0)."""

    keep: torch.Tensor  # (N,) flat sample indices
    prior: PriorSamples  # (N) the 3DMM prior there
    field: FieldOutput  # (N) deformation, density, features, normals
    support: torch.Tensor  # (N,) the field's support (1 near the mesh, 0 at shell_m)

    def sigma(self, R: int, S: int) -> torch.Tensor:
        """(R,S) density with the support applied, 0 where not evaluated."""
        return scatter(self.field.sigma * self.support, self.keep, R * S).reshape(R, S)


Evaluate = Callable[[torch.Tensor], Densities]
"""The field at flat sample indices (those outside its support are dropped)."""


def scatter(values: torch.Tensor, idx: torch.Tensor, n: int) -> torch.Tensor:
    """(n,...) zeros with values (N,...) at idx (N,)."""
    return values.new_zeros(n, *values.shape[1:]).index_copy(0, idx, values)


def concat_densities(parts: list[Densities]) -> Densities:
    """Densities of disjoint sample sets, one after the other."""
    if len(parts) == 1:
        return parts[0]
    cat = lambda items: None if items[0] is None else torch.cat(items)
    prior = PriorSamples(*(cat([getattr(p.prior, f.name) for p in parts]) for f in fields(PriorSamples)))
    out = FieldOutput(*(cat([getattr(p.field, f.name) for p in parts]) for f in fields(FieldOutput)))
    return Densities(torch.cat([p.keep for p in parts]), prior, out, torch.cat([p.support for p in parts]))


def densities_exact(evaluate: Evaluate, R: int, S: int, device: torch.device) -> Densities:
    """The field at every sample (the reference, and training)."""
    return evaluate(torch.arange(R * S, device=device))


def densities_early_stop(evaluate: Evaluate, samples: RaySamples, stop_below: float) -> Densities:
    """The field at the front half of every ray, then at the back half only of rays through whose front half
    more than stop_below of the light passes. Where a ray stops, its back half's samples could add at most
    stop_below to its pixel: the image is within stop_below of densities_exact's."""
    R, S = samples.t_starts.shape
    if stop_below <= 0 or S <= 2:
        return densities_exact(evaluate, R, S, samples.t_starts.device)
    flat = torch.arange(R * S, device=samples.t_starts.device).reshape(R, S)
    front = S // 2 + 1
    first = evaluate(flat[:, :front].reshape(-1))
    optical = (first.sigma(R, S)[:, :front] * samples.deltas[:, :front]).sum(-1)
    lit = torch.exp(-optical) > stop_below
    return concat_densities([first, evaluate(flat[lit, front:].reshape(-1))])


@dataclass
class Shown:
    """The evaluated samples whose colour is computed: all of them (exact), or those that add at least
    min_weight to their pixel (display)."""

    which: torch.Tensor | None  # (M,) indices into the Densities' N samples; None: all N
    field: FieldOutput
    prior: PriorSamples
    keep: torch.Tensor  # (M,) flat sample indices
    view: torch.Tensor  # (M,3) unit, towards the camera
    evaluated: torch.Tensor  # (N,) the Densities' flat sample indices
    rays_shape: tuple[int, int]  # (R,S)

    def to_rays(self, values: torch.Tensor) -> torch.Tensor:
        """Values (M,C) of the shown samples -> (R,S,C), zero at the others."""
        R, S = self.rays_shape
        if self.which is not None:
            values = scatter(values, self.which, len(self.evaluated))
        return scatter(values, self.evaluated, R * S).reshape(R, S, -1)


def shown_samples(d: Densities, weights: torch.Tensor, directions: torch.Tensor, min_weight: float) -> Shown:
    """The samples to colour (see Shown); view directions (R,3) per ray."""
    R, S = weights.shape
    view = (-directions[:, None]).expand(R, S, 3).reshape(-1, 3)[d.keep]
    if min_weight <= 0:  # every sample (training): no subset copies
        return Shown(None, d.field, d.prior, d.keep, view, d.keep, (R, S))
    which = torch.nonzero(weights.reshape(-1)[d.keep] > min_weight).squeeze(1)
    g = d.field
    field_shown = FieldOutput(g.sigma[which], g.rgb[which], g.x_canonical[which],
                              None if g.normal is None else g.normal[which])
    return Shown(which, field_shown, d.prior.take(which), d.keep[which], view[which], d.keep, (R, S))


def weights_of(d: Densities, samples: RaySamples) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """sigma (R,S), the compositing weights (R,S) and the light passing every sample (R,) (Eq. 1)."""
    R, S = samples.t_starts.shape
    sigma = d.sigma(R, S)
    weights, remaining = weights_from_density(sigma, samples.deltas)
    return sigma, weights, remaining


@dataclass
class CoDyNeRFRays:
    """The internals of one render_rays: what the losses and the inspection buffers read."""

    samples: RaySamples
    densities: Densities
    sigma: torch.Tensor  # (R,S)
    weights: torch.Tensor  # (R,S)
    remaining: torch.Tensor  # (R,) light passing every sample
    shown: Shown
    phi: torch.Tensor  # (1,C) the appearance code
    mesh_visibility: torch.Tensor | None  # (M,) the guide mesh's visibility of the key light at the shown samples
    lit: torch.Tensor  # (R,S,3) colour without cast shadows
    factor: torch.Tensor | None  # (R,S,1) share of the lit colour the cast shadows leave
    visibility: torch.Tensor | None  # (M,1) the key light's visibility S at the shown samples
    background: torch.Tensor  # (3,) or (R,3) what the rays see behind the avatar
    point_normal: torch.Tensor | None = None  # (R,S,3)
    point_grad_normal: torch.Tensor | None = None  # (R,S,3)
