"""The CoDyNeRF fields (CoDyNeRF, Eq. 2, 5, 7, 8): residual deformation, density, normals, dynamic
appearance. The effect set decides the inputs and which networks exist (docs/training.md):

| effects   | inputs to the appearance T                 | normals network, density gradients |
|-----------|--------------------------------------------|------------------------------------|
| none      | tau, view direction, phi                   | not built, not computed            |
| shading   | + n                                        | built                              |
| specular  | + n, R                                     | built                              |
| shadows   | + landmarks, expression/pose prior offsets | only with shading or specular      |

Cast shadows as a factor, where the capture records its key light (`FieldConfig.light_dir`): T also gives k,
the key light's share of its colour L, and a small network S gives the key light's visibility at the point from
tau and whether the guide mesh blocks the light there (its shadow map); the colour is L (1 - k (1 - S)). The
render without cast shadows (S = 1) and the shadows alone are then the model's own, not a counterfactual.
Measured on the ICT sun capture's test frames (README, "Cast shadows"): S reading the landmarks and offsets
instead of the mesh, or T without them, lost 4-6 dB; T keeps them (what they carry beyond cast shadows).
Without a recorded light, Eq. 7 as written.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated

import torch
import torch.nn.functional as F
from torch import nn

from models.avatars.codynerf.prior import PriorSamples
from models.avatars.components.encoding import encoded_size, frequency_encoding
from models.avatars.components.mlp import MLP
from models.avatars.components.triplane import TriPlane
from models.ranges import Range

SHADOW_BIAS = 4.0  # the shadow factor's logit at initialisation: 98% of the light reaches every point


@dataclass(frozen=True)
class FieldConfig:
    """Sizes of the fields. Lengths in metres."""

    effects: tuple[str, ...] = ()
    """Lighting effects the avatar models: any of shading, specular, shadows (empty: an ambient capture)."""
    width: Annotated[int, Range(1, 4096)] = 64
    """Hidden width of the deformation, density and appearance networks."""
    deform_code_dim: Annotated[int, Range(0, 4096)] = 8
    """omega: per-frame code of the residual deformation."""
    appearance_code_dim: Annotated[int, Range(0, 4096)] = 8
    """phi: per-frame code of the appearance (camera and exposure changes)."""
    feature_dim: Annotated[int, Range(1, 4096)] = 16
    """tau: features passed from the density to the appearance network."""
    deform_frequencies: int = 4
    prior_frequencies: int = 2
    density_frequencies: int = 6
    view_frequencies: int = 2
    landmark_features: int = 16
    grid_resolution: Annotated[int, Range(0, 4096)] = 0
    """Texels a side of the canonical tri-plane features that the density network reads beside its position
    encoding (components/triplane.py); 0: none. Off by default: on the tracked d3 video (`none`, 30 minutes, 256
    texels of 8 features a plane) the field fit its training frames worse (photometric error 0.0032 against
    0.0018 about step 2500) and held-out frames 2.0 dB worse (23.17 against 25.17 dB), with 11% fewer steps (some
    of them lost to tests run beside it)."""
    grid_features: Annotated[int, Range(1, 256)] = 8
    """Features per plane of the tri-plane."""
    scale_m: Annotated[float, Range(0, 100, above=True)] = 0.25
    """Half the extent that position encodings cover without aliasing."""
    light_dir: tuple[float, float, float] | None = None
    """The capture's key light (world, towards the light), where its lighting record has one. With shadows,
    the colour is then T's L (1 - k (1 - S)): S, the key light's visibility, from tau and the guide mesh's shadow
    map (looked up by the avatar, render/shadow_map.py), so the render without cast shadows (S = 1) is the
    model's own.
    Without a light (a tracked video, avatars trained before), Eq. 7 as written: one T reads everything."""

    @property
    def shadow_factor(self) -> bool:
        return self.light_dir is not None and "shadows" in self.effects

    @property
    def needs_normals(self) -> bool:
        return "shading" in self.effects or "specular" in self.effects


@dataclass
class FieldOutput:
    sigma: torch.Tensor  # (P,) density, 1/m
    rgb: torch.Tensor  # (P,3) in [0,1] (from `geometry` alone: tau, the features for the appearance)
    x_canonical: torch.Tensor  # (P,3)
    normal: torch.Tensor | None = None  # (P,3) predicted (Eq. 8)
    grad_normal: torch.Tensor | None = None  # (P,3) -grad sigma / |grad sigma|


def safe_normalize(v: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """v / |v|, and 0 (with a zero gradient) where v is 0: zero density gradients stay finite."""
    n2 = (v * v).sum(-1, keepdim=True)
    return v * torch.rsqrt(n2.clamp_min(eps)) * (n2 > eps)


class CoDyNeRFField(nn.Module):
    def __init__(self, cfg: FieldConfig, n_landmarks: int, grid_box: tuple[torch.Tensor, torch.Tensor] | None = None):
        """grid_box: the canonical box (min, max) the tri-plane covers (needed with cfg.grid_resolution)."""
        super().__init__()
        self.cfg = cfg
        c = cfg
        self.grid = None
        if c.grid_resolution:
            if grid_box is None:
                raise ValueError("a field with tri-plane features needs the canonical box they cover")
            self.grid = TriPlane(*grid_box, c.grid_resolution, c.grid_features)
        d_def = encoded_size(3, c.deform_frequencies) + encoded_size(3, c.prior_frequencies) + c.deform_code_dim
        self.deform = MLP(d_def, 3, c.width, 3, zero_last=True)
        d_density = encoded_size(3, c.density_frequencies) + 1 + (0 if self.grid is None else self.grid.out_features)
        self.density = MLP(d_density, 1 + c.feature_dim, c.width, 3)
        # N starts as the mesh normal and learns a correction (zero-initialised last layer): Eq. 9 holds at
        # the start and the appearance sees sensible normals from the first step.
        self.normals = MLP(3 + 3 + 1, 3, 32, 2, zero_last=True) if c.needs_normals else None
        d_app = c.feature_dim + encoded_size(3, c.view_frequencies) + c.appearance_code_dim
        if c.needs_normals:
            d_app += 3
        if "specular" in c.effects:
            d_app += encoded_size(3, c.view_frequencies)
        self.landmarks = self.shadow_net = None
        if "shadows" in c.effects:
            self.landmarks = nn.Linear(3 * n_landmarks, c.landmark_features)
            d_app += c.landmark_features + 6
        if c.shadow_factor:  # starts fully lit (see SHADOW_BIAS): shadows are learnt where the images call for them
            self.shadow_net = MLP(c.feature_dim + 1, 1, 32, 2, zero_last=True)
        # With a shadow factor, a fourth output: the share of the lit colour that the key light gives (k below).
        self.appearance_net = MLP(d_app, 4 if self.shadow_net is not None else 3, c.width, 2)

    def geometry(
        self,
        x: torch.Tensor,  # (P,3) world points
        prior: PriorSamples,
        omega: torch.Tensor,  # (P, deform_code_dim), or (1, deform_code_dim) shared by every point
        create_graph: bool = False,  # keep the graph of density gradients (training through the normals)
        occupied: Callable[[torch.Tensor], torch.Tensor] | None = None,  # canonical points -> may hold density
        mesh_normals: bool = False,  # the mesh's normals stand in for N and the density gradient (none computed)
    ) -> FieldOutput:
        """Deformation, density and normals (Eq. 2, 5, 8); rgb is left empty for `appearance` to fill. With
        `occupied` (display), the density network runs only where the deformed, canonical point may hold
        density; elsewhere density and features are zero. With `mesh_normals` the normals are the mesh's
        (what N starts as, its last layer being zero), at the cost of a network without normals."""
        c = self.cfg
        s = c.scale_m
        gradients = c.needs_normals and not mesh_normals
        if gradients and not x.requires_grad:
            x = x.detach().requires_grad_(True)
        # Density gradients need autograd even when rendering for display (under no_grad, not inference_mode).
        with torch.enable_grad() if gradients else contextlib.nullcontext():
            x_prior = x + prior.offset  # Eq. 2: the prior's part of x_can
            delta = self.deform(torch.cat([frequency_encoding(x, c.deform_frequencies, s),
                                           frequency_encoding(prior.offset, c.prior_frequencies, s)], -1), omega)
            x_can = x_prior + delta
            if occupied is None:
                sigma, tau = self.canonical_density(x_can, prior.distance)
            else:
                idx = torch.nonzero(occupied(x_can.detach())).squeeze(1)
                s_k, t_k = self.canonical_density(x_can[idx], prior.distance[idx])
                sigma = s_k.new_zeros(len(x)).index_copy(0, idx, s_k)
                tau = t_k.new_zeros(len(x), t_k.shape[1]).index_copy(0, idx, t_k)
            normal = grad_normal = None
            if c.needs_normals and mesh_normals:
                normal = grad_normal = safe_normalize(prior.mesh_normal)
            elif c.needs_normals:
                (grad,) = torch.autograd.grad(sigma.sum(), x, create_graph=create_graph, retain_graph=True)
                grad_normal = safe_normalize(-grad)
                normal = safe_normalize(prior.mesh_normal + self.normals(torch.cat(
                    [prior.mesh_normal, grad_normal, prior.distance[:, None] / c.scale_m], -1)))
        return FieldOutput(sigma, tau, x_can, normal, grad_normal)

    def canonical_density(self, x_can: torch.Tensor, distance: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Density (P,) and features tau (P,F) at canonical points, given their distance to the mesh (Eq. 5)."""
        c = self.cfg
        inputs = [frequency_encoding(x_can, c.density_frequencies, c.scale_m), distance[:, None]]
        if self.grid is not None:
            inputs.append(self.grid(x_can))
        raw = self.density(torch.cat(inputs, -1))
        return F.softplus(raw[:, 0] - 1.0) * 100.0, raw[:, 1:]  # densities of order 100 / m: opaque within ~1 cm

    def appearance(
        self,
        geo: FieldOutput,  # from `geometry` (rgb holds tau there)
        prior: PriorSamples,
        view_dir: torch.Tensor,  # (P,3) unit, from the point towards the camera
        phi: torch.Tensor,  # (P, appearance_code_dim), or (1, appearance_code_dim) shared by every point
        landmarks: torch.Tensor | None = None,  # (1, 3L) head-centred
        mesh_light: torch.Tensor | None = None,  # (P,) the guide mesh's visibility of the key light (shadow factor)
    ) -> torch.Tensor:
        """Colour (P,3) in [0,1] (Eq. 7)."""
        lit, factor, _ = self.appearance_terms(geo, prior, view_dir, phi, landmarks, mesh_light)
        return lit if factor is None else lit * factor

    def appearance_terms(
        self,
        geo: FieldOutput,
        prior: PriorSamples,
        view_dir: torch.Tensor,
        phi: torch.Tensor,
        landmarks: torch.Tensor | None = None,
        mesh_light: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
        """The colour without cast shadows L (P,3), the factor F (P,1) in (0,1) that cast shadows leave of it,
        whose product is the colour, and the key light's visibility S (P,1); F and S are None without a shadow
        factor (the colour is then L).

        F = 1 - k (1 - S): S, from the shadow network, is how much of the key light reaches the point (a
        visibility: 1 lit, 0 blocked), and k, from the appearance network beside L, is the share of L that
        the key light gives there (it depends on the normal, the light and the albedo, which the appearance
        network sees and S does not). So a fully shadowed point keeps its ambient part L (1 - k), as in the
        capture's light, and S only has to say where the light is blocked."""
        c = self.cfg
        if c.shadow_factor:
            if mesh_light is None:
                raise ValueError("this avatar's shadow factor reads the guide mesh's shadow map: pass mesh_light")
            visibility = torch.sigmoid(SHADOW_BIAS + self.shadow_net(torch.cat([geo.rgb, mesh_light[:, None]], -1)))
        inputs = [geo.rgb, frequency_encoding(view_dir, c.view_frequencies)]
        if c.needs_normals:
            inputs.append(geo.normal)
        if "specular" in c.effects:
            reflect = 2 * (view_dir * geo.normal).sum(-1, keepdim=True) * geo.normal - view_dir
            inputs.append(frequency_encoding(reflect, c.view_frequencies))
        if self.landmarks is not None:
            lm = self.landmarks(landmarks).expand(len(view_dir), -1)
            inputs += [lm, prior.expression_offset / c.scale_m, prior.pose_offset / c.scale_m]
        out = torch.sigmoid(self.appearance_net(torch.cat(inputs, -1), phi, code_at=c.feature_dim + encoded_size(
            3, c.view_frequencies)))
        if self.shadow_net is None:
            return out, None, None
        return out[:, :3], 1.0 - out[:, 3:] * (1.0 - visibility), visibility

