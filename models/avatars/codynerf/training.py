"""CoDyNeRF's training losses (CoDyNeRF, Eq. 10-14) on rendered rays, with their weights and schedules (Eq. 9, on the
mesh's vertices, is the avatar's mesh_normal_term)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from models.avatars.codynerf.render import CoDyNeRFRays
from models.avatars.components import losses


@dataclass(frozen=True)
class LossWeights:
    mesh_normals: float = 0.1  # Eq. 9
    normals_facing: float = 0.1  # Eq. 10
    normal_consistency: float = 0.1  # Eq. 13
    consistency_start: float = 0.3
    """Eq. 13 is off for this fraction of the run, then ramps up linearly over the next `consistency_ramp`:
    tying density gradients to the normals before the density has settled wrecks the density (measured:
    validation PSNR 21.8 dB with Eq. 13 from the start vs 30.5 without, after 1000 steps)."""
    consistency_ramp: float = 0.3
    consistency_shapes_density: bool = True
    """Eq. 13 pulls both ways: the predicted normals towards the density's gradient and the density's gradient
    (second derivatives) towards the normals. Off, it pulls only the normals (the density's gradient detached, no
    second derivatives): on the tracked d3 video (`all`, 30 minutes) the two-way pull wrecked the density the
    moment it came in (training photometric error 0.0019 to 0.037 within 100 steps, still 0.02 400 steps on),
    where the synthetic captures' clean surfaces took it well (README: `all` 4 dB over `none`)."""
    mesh_normals_first: bool = False
    """Until Eq. 13 comes in (consistency_start), the guide mesh's normals stand in for the predicted ones (which
    start as them) and no density gradient is computed: that part of the run costs what `none` costs. On for
    tracked videos, where `all` got 58% of `none`'s steps in 30 minutes and ended 0.8 dB below it on d3."""
    cauchy: float = 1e-3  # Eq. 14 (1e-3 vs 1e-4: val PSNR 30.7 vs 30.1 dB at 1000 steps, a sparser field)
    cauchy_c: float = 100.0
    codes: float = 1e-3
    shadow: float = 0.003
    """The light the shadow factor blocks, per ray (weights detached): without it the factor could dim the
    whole head and the lit colour brighten to match, so "without cast shadows" would mean nothing. Small
    against a shadow's photometric error (0.15 darker: 0.02 a ray) and 0 (dimming moves into the lit colour)
    where the factor dims what the lit colour could show."""
    shadow_start: float = 0.5
    """The shadow term is off for this fraction of the run, then ramps up over `shadow_ramp`: on from the start
    (weight 0.01) it held the factor at 1 before anything called for shadows (measured with the factor's first
    form, colour = L S with S on the shadow inputs: S > 0.9999 everywhere after 3 minutes on the ICT sun capture;
    without the term, down to 0.44 in the shadows)."""
    shadow_ramp: float = 0.2
    mesh_normal_vertices: int = 256
    pose_corrections: float = 1e-4
    """The prior on a tracked video's per-frame pose corrections (units of 0.01 rad and 2 mm, squared): at
    those sizes it costs 2e-4, a twentieth of a real capture's photometric error (about 4e-3)."""


def ramp(progress: float, start: float, length: float) -> float:
    """0 before `start`, rising linearly to 1 over `length` (fractions of the run).

    >>> ramp(0.5, 0.25, 0.5), ramp(0.1, 0.3, 0.3), ramp(0.9, 0.3, 0.3)
    (0.5, 0.0, 1.0)
    """
    return min(max((progress - start) / max(length, 1e-9), 0.0), 1.0)


def consistency_weight(w: LossWeights, progress: float) -> float:
    """Eq. 13's weight at this point of the run (see LossWeights.consistency_start)."""
    return w.normal_consistency * ramp(progress, w.consistency_start, w.consistency_ramp)


def ray_terms(w: LossWeights, r: CoDyNeRFRays, rgb: torch.Tensor, target: torch.Tensor, directions: torch.Tensor,
              progress: float, codes: tuple[torch.Tensor, ...]) -> dict[str, torch.Tensor]:
    """The losses on rendered rays, weighted: photometric (R,3) colours against the capture's, Cauchy sparsity
    (Eq. 14), the codes' L2, the light the shadow factor takes away, and with normals Eq. 10 and Eq. 13."""
    parts = {"photometric": losses.photometric(rgb, target),
             "cauchy": w.cauchy * losses.cauchy_sparsity(r.sigma, w.cauchy_c),
             "codes": w.codes * losses.code_l2(*codes)}
    if r.factor is not None:
        parts["shadow"] = ramp(progress, w.shadow_start, w.shadow_ramp) * w.shadow * \
            losses.blocked_light(r.weights, r.factor[..., 0])
    if r.point_normal is not None:
        parts["normals_facing"] = w.normals_facing * losses.normals_facing_camera(r.weights, r.point_normal,
                                                                                  directions)
        consistency = consistency_weight(w, progress)
        if consistency > 0:
            grad = r.point_grad_normal if w.consistency_shapes_density else r.point_grad_normal.detach()
            parts["normal_consistency"] = consistency * losses.top_k_normal_consistency(r.weights, r.point_normal,
                                                                                        grad)
    return parts
