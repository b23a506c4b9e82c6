"""The NerFACE baseline (Gafni et al. 2021): a radiance field in head-canonical space conditioned on the expression
and a learned per-frame latent code, rendered by dense coarse-to-fine sampling, in the same harness as the
avatar (same datasets, trainer, checkpoints, eval and render commands).

What it keeps from the paper: rays are moved into the head's canonical frame by the tracked rigid pose; an
8x256 MLP with a skip at layer 4 reads 10-frequency positions with the expression and the latent code, and a
colour branch reads 4-frequency view directions; 64 stratified coarse samples and 64 fine samples drawn from
the coarse weights, with a coarse and a fine network; the background is the colour of the last sample (what
light passes every sample); training rays fall mostly inside the face's box.

The expression vector is the head model's expression coefficients with the non-rigid joint rotations (neck,
jaw, eyes) appended; the rigid pose is the best-fit rotation and translation (Kabsch) taking the expressed,
unposed mesh onto the posed one, so any head model works without knowing its joint layout.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Annotated, Any, ClassVar

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from models.avatars.base import Avatar, RayOutput, TrainingBatch
from models.avatars.components import losses
from models.avatars.components.codes import CodeKeys, frame_code
from models.avatars.components.encoding import encoded_size, frequency_encoding
from models.avatars.components.plate import Plate
from models.avatars.components.rigid import head_pose
from models.avatars.components.views import CaptureViews
from models.head.controls import Controls
from models.head.model import HeadModel
from models.ranges import Range, check_config
from render.camera import Camera
from render.gl.raster import Rasterizer
from render.rays import Coverage, Rays
from render.sampling import RaySamples, stratified
from render.volume import composite, expected_depth, ray_aabb_intersect, sample_pdf, weights_from_density

NONRIGID_JOINTS = ("neck", "jaw", "eye_l", "eye_r")


@dataclass(frozen=True)
class NerfaceConfig:
    """NerFACE's published sizes."""

    width: Annotated[int, Range(1, 4096)] = 256
    depth: Annotated[int, Range(2, 64)] = 8
    """Hidden layers of the density branch (a skip joins the input again after half of them)."""
    position_frequencies: int = 10
    view_frequencies: int = 4
    latent_dim: Annotated[int, Range(0, 4096)] = 32
    coarse_samples: Annotated[int, Range(1, 4096)] = 64
    fine_samples: Annotated[int, Range(0, 4096)] = 64
    box_margin_m: Annotated[float, Range(0, 1)] = 0.05
    """The canonical head box (the template's bounds grown by this much) bounds every ray."""
    face_ray_fraction: Annotated[float, Range(0, 1)] = 0.95
    """Share of training rays drawn inside the face's box; the rest anywhere in the image."""
    chunk_rays: Annotated[int, Range(1, 1 << 22)] = 1024


class NerfaceMLP(nn.Module):
    """Density and colour of canonical points given a condition vector (expression and latent code)."""

    def __init__(self, cfg: NerfaceConfig, condition_dim: int):
        super().__init__()
        self.cfg = cfg
        d_in = encoded_size(3, cfg.position_frequencies) + condition_dim
        half = cfg.depth // 2
        self.first = nn.ModuleList(nn.Linear(d_in if k == 0 else cfg.width, cfg.width) for k in range(half))
        self.second = nn.ModuleList(nn.Linear(cfg.width + d_in if k == 0 else cfg.width, cfg.width)
                                    for k in range(cfg.depth - half))
        self.sigma = nn.Linear(cfg.width, 1)
        self.feature = nn.Linear(cfg.width, cfg.width)
        self.colour = nn.Sequential(nn.Linear(cfg.width + encoded_size(3, cfg.view_frequencies), cfg.width // 2),
                                    nn.ReLU(inplace=True), nn.Linear(cfg.width // 2, 3))

    def forward(self, x: torch.Tensor, view: torch.Tensor, condition: torch.Tensor, scale: float
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """(P,3) canonical points, (P,3) unit view directions, (P,C) conditions -> sigma (P,), rgb (P,3)."""
        h_in = torch.cat([frequency_encoding(x, self.cfg.position_frequencies, scale), condition], -1)
        h = h_in
        for layer in self.first:
            h = F.relu(layer(h))
        h = torch.cat([h, h_in], -1)
        for layer in self.second:
            h = F.relu(layer(h))
        sigma = F.softplus(self.sigma(h)[:, 0] - 1.0) * 100.0  # the avatar's density scale, per metre
        view_enc = frequency_encoding(view, self.cfg.view_frequencies)
        rgb = torch.sigmoid(self.colour(torch.cat([self.feature(h), view_enc], -1)))
        return sigma, rgb


@dataclass
class NerfaceGeometry:
    """One frame as NerFACE sees it: the rigid head pose and the expression vector (and the posed mesh, which
    training uses to find the face's box)."""

    rotation: torch.Tensor  # (3,3) canonical -> world
    translation: torch.Tensor  # (3,)
    expression: torch.Tensor  # (1,E)
    posed: torch.Tensor  # (V,3)
    code_weights: torch.Tensor | None = None  # (N,) the training frames' share of new controls' code (None: mean)

    def to(self, device: torch.device | str) -> NerfaceGeometry:
        weights = None if self.code_weights is None else self.code_weights.to(device)
        return NerfaceGeometry(self.rotation.to(device), self.translation.to(device), self.expression.to(device),
                               self.posed.to(device), weights)


@dataclass
class NerfaceRays:
    """The internals of one render_rays: the coarse pass's colours (trained too) and the fine pass's samples."""

    coarse_rgb: torch.Tensor  # (R,3)
    weights: torch.Tensor  # (R,S)
    sigma: torch.Tensor  # (R,S)
    samples: RaySamples


def face_box(hit: np.ndarray, margin_px: int) -> np.ndarray:
    """(H,W) the bounding box of the mesh's pixels grown by margin_px: where NerFACE draws most rays."""
    box = np.zeros_like(hit)
    if hit.any():
        rows, cols = np.nonzero(hit.any(1))[0], np.nonzero(hit.any(0))[0]
        top, left = max(rows[0] - margin_px, 0), max(cols[0] - margin_px, 0)
        box[top:rows[-1] + margin_px + 1, left:cols[-1] + margin_px + 1] = True
    return box


class NerfaceAvatar(Avatar):
    """The baseline, behind the avatar interface."""

    name: ClassVar[str] = "nerface"
    rays_per_step: ClassVar[int] = 256
    config_class: ClassVar[type] = NerfaceConfig
    """Each of its rays costs 128 samples of an 8x256 MLP."""

    def __init__(self, head_model: HeadModel, cfg: NerfaceConfig, n_frames: int, background: np.ndarray,
                 codes_weight: float = 1e-3):
        super().__init__(head_model, n_frames, background)
        self.cfg = cfg
        self.codes_weight = codes_weight
        self.expression_dim = head_model.num_expression + 3 * len(NONRIGID_JOINTS)
        condition = self.expression_dim + cfg.latent_dim
        self.coarse = NerfaceMLP(cfg, condition)
        self.fine = NerfaceMLP(cfg, condition)
        self.latent = nn.Embedding(n_frames, cfg.latent_dim)
        nn.init.zeros_(self.latent.weight)
        template = torch.as_tensor(head_model.template, dtype=torch.float32)
        self.register_buffer("box_min", template.min(0).values - cfg.box_margin_m)
        self.register_buffer("box_max", template.max(0).values + cfg.box_margin_m)
        self.scale_m = float((self.box_max - self.box_min).max()) / 2
        self.plate, self.views = Plate(), CaptureViews()
        """What the capture kept (components/): its background plate, where its camera stood."""
        self.code_keys = CodeKeys(head_model.num_expression)
        """The training frames' control keys: new controls take the nearest frames' codes."""

    # ---- making and describing -------------------------------------------------------------------------
    def note_views(self, frames) -> None:
        """Where the capture's camera stood, if it stood still (its colour reads the view from there)."""
        self.views.note(frames.origins, None, self.background.device)

    @classmethod
    def for_capture(cls, head_model: HeadModel, n_frames: int, background: np.ndarray, effects: tuple[str, ...],
                    lighting: dict | None, config: NerfaceConfig | None = None) -> NerfaceAvatar:
        """NerFACE models no lighting effects: the effect set and the lighting record are not read (as before the
        avatar interface: `train --model nerface` takes the default --effects all and trains the baseline)."""
        del effects, lighting
        return cls(head_model, config or NerfaceConfig(), n_frames, background)

    @classmethod
    def from_meta(cls, head_model: HeadModel, meta: dict) -> NerfaceAvatar:
        cfg = NerfaceConfig(**meta["nerface"])
        check_config(cfg)
        return cls(head_model, cfg, int(meta["frames"]),
                   np.asarray(meta["background"], np.float32))

    def meta(self) -> dict:
        return {"model": self.name, "effects": [], "nerface": asdict(self.cfg)}

    def describe_rendering(self) -> str:
        return f"{self.cfg.coarse_samples}+{self.cfg.fine_samples} samples, {self.cfg.depth}x{self.cfg.width} MLPs"

    # ---- per frame -------------------------------------------------------------------------------------
    @torch.no_grad()
    def geometry(self, controls: Controls, time_s: float | None = None) -> NerfaceGeometry:
        unposed = Controls(shape=controls.shape, expression=controls.expression)
        v, joints, _ = self.head.pose([unposed, controls])
        rotation, translation = head_pose(self.head_model, controls, v, joints)
        expr = np.zeros(self.expression_dim, np.float32)
        n = min(len(controls.expression), self.head_model.num_expression)
        expr[:n] = controls.expression[:n]
        for k, joint in enumerate(NONRIGID_JOINTS):
            expr[self.head_model.num_expression + 3 * k:self.head_model.num_expression + 3 * k + 3] = \
                controls.rotation(joint)
        return NerfaceGeometry(rotation, translation, torch.as_tensor(expr)[None].to(rotation.device), v[1],
                               self.code_keys.weights(controls, time_s))

    def frame_geometry(self, controls: Controls, rasterizer: Rasterizer | None, time_s: float | None = None
                       ) -> NerfaceGeometry:
        del rasterizer  # NerFACE samples every ray densely; it does not need the mesh
        return self.geometry(controls, time_s)

    def image_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        """Every pixel (rays that miss the head's box see the background)."""
        return np.ones((camera.height_px, camera.width_px), bool)

    def training_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        """The face's box (the mesh's pixels' bounding box, grown a little)."""
        return face_box(raster.hit, margin_px=max(2, camera.width_px // 32))

    def draw_training_pixels(self, active: torch.Tensor, n_pixels: int, n: int, generator: torch.Generator
                             ) -> torch.Tensor:
        """Most rays in the face's box, the rest anywhere in the image (face_ray_fraction)."""
        pick = active[torch.randint(len(active), (n,), generator=generator)]
        n_any = round(n * (1 - self.cfg.face_ray_fraction))
        pick[:n_any] = torch.randint(n_pixels, (n_any,), generator=generator)
        return pick

    def codes(self, frame: int | None, weights: torch.Tensor | None = None) -> torch.Tensor:
        """The latent code (1,C) of a training frame; for new controls (frame None) the training frames' codes
        blended by `weights` (N,) (Avatar.code_weights), or without them the mean code."""
        return frame_code(self.latent, frame, weights)

    @property
    def chunk_rays(self) -> int:
        return self.cfg.chunk_rays

    # ---- rays ------------------------------------------------------------------------------------------
    def render_rays(self, rays: Rays, geometry: NerfaceGeometry, frame: int | None,
                    generator: torch.Generator | None = None, training: bool = False, options: Any = None
                    ) -> RayOutput:
        """The fine pass's colour, opacity and depth; the coarse pass's colours in the internals (both are
        trained). Display and training render alike (no shortcuts, whatever the options)."""
        del training, options
        c = self.cfg
        R = len(rays)
        geo, latent = geometry, self.codes(frame, geometry.code_weights)
        rot, tr = geo.rotation, geo.translation
        o = (rays.origins - tr) @ rot  # R^T (o - t), row vectors
        d = rays.directions @ rot
        near, far, hits = ray_aabb_intersect(o, d, self.box_min, self.box_max)
        near, far = torch.where(hits, near, 0.0), torch.where(hits, far, 0.0)
        condition = torch.cat([geo.expression, latent], -1).expand(R, -1)

        def run(net: NerfaceMLP, t0: torch.Tensor, t1: torch.Tensor):
            S = t0.shape[1]
            t_mid = 0.5 * (t0 + t1)
            pts = (o[:, None] + d[:, None] * t_mid[..., None]).reshape(-1, 3)
            view = (-d[:, None]).expand(R, S, 3).reshape(-1, 3)
            fixed_view = self.views.towards_camera(pts @ rot.T + tr)  # a tracked video's view
            view = view if fixed_view is None else fixed_view @ rot
            sigma, rgb = net(pts, view, condition.repeat_interleave(S, 0), self.scale_m)
            sigma = sigma.reshape(R, S) * hits[:, None]
            weights, remaining = weights_from_density(sigma, t1 - t0)
            return weights, remaining, rgb.reshape(R, S, 3), sigma, t_mid

        t0, t1 = stratified(near, far, c.coarse_samples, generator)
        w_c, rem_c, rgb_c, _, _ = run(self.coarse, t0, t1)
        coarse_rgb = composite(w_c, rgb_c, rem_c, self.ray_background(rays))
        edges = torch.cat([t0, t1[:, -1:]], 1)
        t_fine = sample_pdf(edges, w_c.detach(), c.fine_samples, generator)
        t_all = torch.sort(torch.cat([0.5 * (t0 + t1), t_fine.detach()], 1), dim=1).values
        # Intervals about the sorted samples, bounded by the box.
        mids = 0.5 * (t_all[:, 1:] + t_all[:, :-1])
        f0 = torch.cat([near[:, None], mids], 1)
        f1 = torch.cat([mids, far[:, None]], 1)
        w, rem, rgb, sigma, t_mid = run(self.fine, f0, f1)
        buffers = {"rgb": composite(w, rgb, rem, self.ray_background(rays)), "opacity": w.sum(-1),
                   "depth": expected_depth(w, t_mid)}
        return RayOutput(buffers, NerfaceRays(coarse_rgb, w, sigma, RaySamples(f0, f1, hits)))

    def loss_terms(self, batch: TrainingBatch) -> dict[str, torch.Tensor]:
        """NerFACE's losses: photometric on the coarse and the fine pass, and a small latent-code prior."""
        out = self.render_rays(batch.rays, batch.geometry, batch.frame, batch.generator, training=True)
        return {"photometric": losses.photometric(out.buffers["rgb"], batch.target),
                "photometric_coarse": losses.photometric(out.internals.coarse_rgb, batch.target),
                "codes": self.codes_weight * losses.code_l2(self.codes(batch.frame))}
