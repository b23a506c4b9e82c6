"""CoDyNeRF's training losses (paper 000, Eq. 9-14) on one frame's rays, with their weights and schedules."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from models.avatars.base import TrainingBatch
from models.avatars.codynerf.prior import deformation_prior
from models.avatars.components import losses

if TYPE_CHECKING:
    from models.avatars.codynerf.avatar import CoDyNeRFAvatar


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


def ramp(progress: float, start: float, length: float) -> float:
    """0 before `start`, rising linearly to 1 over `length` (fractions of the run).

    >>> ramp(0.5, 0.25, 0.5), ramp(0.1, 0.3, 0.3), ramp(0.9, 0.3, 0.3)
    (0.5, 0.0, 1.0)
    """
    return min(max((progress - start) / max(length, 1e-9), 0.0), 1.0)


def consistency_weight(w: LossWeights, progress: float) -> float:
    """Eq. 13's weight at this point of the run (see LossWeights.consistency_start)."""
    return w.normal_consistency * ramp(progress, w.consistency_start, w.consistency_ramp)


def loss_terms(avatar: CoDyNeRFAvatar, batch: TrainingBatch) -> dict[str, torch.Tensor]:
    """The losses of Eq. 9-14 (and the shadow factor's) on one frame's rays, weighted."""
    w = avatar.loss_weights
    consistency = consistency_weight(w, batch.progress)
    # Second derivatives only while Eq. 13 ties density gradients to the normals: before that the density
    # gradient is an input the normals network reads, not something to train through.
    second_order = avatar.field_cfg.needs_normals and consistency > 0
    out = avatar.render_rays(batch.rays, batch.geometry, batch.frame, batch.generator, training=True,
                             create_graph=second_order)
    r = out.internals
    omega, phi = avatar.codes(batch.frame)
    parts = {"photometric": losses.photometric(out.buffers["rgb"], batch.target),
             "cauchy": w.cauchy * losses.cauchy_sparsity(r.sigma, w.cauchy_c),
             "codes": w.codes * losses.code_l2(omega, phi)}
    if r.factor is not None:
        parts["shadow"] = ramp(batch.progress, w.shadow_start, w.shadow_ramp) * w.shadow * \
            losses.blocked_light(r.weights, r.factor[..., 0])
    if r.point_normal is not None:
        parts["normals_facing"] = w.normals_facing * losses.normals_facing_camera(
            r.weights, r.point_normal, batch.rays.directions)
        if consistency > 0:
            parts["normal_consistency"] = consistency * losses.top_k_normal_consistency(
                r.weights, r.point_normal, r.point_grad_normal)
        parts["mesh_normals"] = w.mesh_normals * mesh_normal_term(avatar, batch, second_order)
    return parts


def mesh_normal_term(avatar: CoDyNeRFAvatar, batch: TrainingBatch, second_order: bool) -> torch.Tensor:
    """Eq. 9 on a random subset of the frame's posed vertices (DistToMesh = 0 there)."""
    geo = batch.geometry
    n = avatar.loss_weights.mesh_normal_vertices
    idx = torch.randint(len(geo.meshes.posed), (n,), generator=batch.generator).to(geo.meshes.posed.device)
    pts = geo.meshes.posed[idx]
    prior = deformation_prior(pts, geo.meshes, avatar.render_cfg.prior_falloff_m, geo.tree)
    omega, _ = avatar.codes(batch.frame)
    out = avatar.field.geometry(pts, prior, omega.expand(n, -1), create_graph=second_order)
    return losses.mesh_normal_consistency(out.normal, geo.meshes.normals[idx])
