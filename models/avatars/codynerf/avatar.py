"""The CoDyNeRF avatar (docs/models.md): a head model, the CoDyNeRF fields and per-frame codes, rendered along rays.

Rendering a frame: the posed mesh is rasterized (GL) for the distance to its surface along each pixel's ray;
rays near the head's silhouette sample a shell about the surface (or the head's box where they miss the
mesh), every other pixel is background. Samples take the 3DMM prior (Eq. 3-4), the fields (Eq. 2, 5, 7, 8),
and are composited over the background (Eq. 1); the steps are in render.py.
"""

from __future__ import annotations

import contextlib
from dataclasses import asdict, dataclass, replace
from typing import Annotated, Any, ClassVar

import numpy as np
import torch
from scipy.ndimage import binary_dilation
from torch import nn

from models.avatars.base import BACKGROUND, Avatar, RayOutput, TrainingBatch
from models.avatars.codynerf import render
from models.avatars.codynerf.field import CoDyNeRFField, FieldConfig
from models.avatars.codynerf.geometry import FrameGeometry, frame_geometry, with_light_depth
from models.avatars.codynerf.occupancy import OccupancyGrid
from models.avatars.codynerf.prior import deformation_prior, nearest_vertices, prior_within, vertex_tree
from models.avatars.codynerf.training import LossWeights, consistency_weight, ray_terms
from models.avatars.components import losses
from models.avatars.components.codes import CodeKeys, frame_code
from models.avatars.components.plate import Plate
from models.avatars.components.poses import PoseCorrected
from models.avatars.components.views import CaptureViews
from models.avatars.effects import key_light_dir
from models.avatars.mesh import MeshField, front_eye
from models.avatars.quality import Quality
from models.head.controls import Controls
from models.head.lbs import rotation_matrix_from_axis_angle
from models.head.model import HeadModel
from models.ranges import Range, check_config
from render.camera import Camera
from render.gl.raster import Rasterizer
from render.rays import Coverage, Rays
from render.sampling import fine_samples
from render.volume import composite, expected_depth


@dataclass(frozen=True)
class RenderConfig:
    """How many samples, where. Lengths in metres."""

    samples_per_ray: Annotated[int, Range(1, 4096)] = 12
    """Samples in the shell about the surface (or across the box for rays that miss the mesh)."""
    shell_m: Annotated[float, Range(0, 1, above=True)] = 0.03
    """Half-thickness of the shell about the rasterized surface."""
    box_margin_m: Annotated[float, Range(0, 1)] = 0.03
    """The head's box: the posed mesh's bounds grown by this much."""
    silhouette_px: Annotated[int, Range(0, 1000)] = 3
    """Rays within this many pixels of the mesh's silhouette are rendered (at least as many as the shell
    spans at the head's distance); farther ones are background."""
    silhouette_m: Annotated[float, Range(0, 1)] | None = None
    """How far the capture's foreground reaches beyond the mesh's silhouette (hair, shoulders), metres,
    measured from the capture's masks when training starts; None (no masks): the whole shell."""
    prior_falloff_m: Annotated[float, Range(0, 10, above=True)] = 0.05
    """Length over which the 3DMM prior fades with distance from the mesh."""
    stop_below: Annotated[float, Range(0, 1)] = 1e-3
    """Display ends a ray early once less than this share of the light gets through its front half."""
    occupancy: bool = False
    """Display skips the density network where the occupancy grid says the canonical point is empty. Off:
    measured on the 25-minute ICT sun avatar (all effects), it cost 4-6 dB PSNR on test frames (likely cause,
    not proven: 4 random points per 5 mm cell miss a sharp surface's thin shell); an earlier, cheaper lookup
    saved 8% of the time (149 to 137 ms at 128 px)."""
    bf16: bool = False
    """Display runs the networks in bfloat16 (training is always float32)."""
    fine_samples: Annotated[int, Range(0, 4096)] = 0
    """Display: a second pass adds this many samples where the first pass's weights lie (0: one pass)."""
    min_weight: Annotated[float, Range(0, 1)] = 1e-4
    """Display skips the colour of samples that add less than this to their pixel (training never does)."""
    chunk_rays: Annotated[int, Range(1, 1 << 22)] = 4096
    """Rays per batch when rendering an image (memory)."""
    dense_samples: Annotated[int, Range(0, 1 << 16)] = 0
    """The slow reference (tests): ignore the mesh and spread this many samples over the head's box on every
    pixel's ray, with no shortcut (0: the shell sampler)."""


MAX_REACH_M = 0.10
"""The farthest beyond the guide mesh an avatar models (hair, collar): the field's support and its sampling cost
grow with it."""


def silhouette_margin_px(cfg: RenderConfig, camera: Camera, depth: np.ndarray) -> int:
    """Pixels around the mesh's silhouette to render: how far the capture's foreground reaches beyond the
    mesh (cfg.silhouette_m; else the shell, as density lives within shell_m of the mesh) at the nearest
    surface's distance, at least cfg.silhouette_px."""
    finite = depth[np.isfinite(depth)]
    if len(finite) == 0:
        return cfg.silhouette_px
    reach = cfg.shell_m if cfg.silhouette_m is None else min(cfg.silhouette_m, cfg.shell_m)
    return max(cfg.silhouette_px, int(np.ceil(reach * camera.focal_px() / max(finite.min(), 1e-3))))


def active_pixels(cfg: RenderConfig, camera: Camera, raster: Coverage) -> np.ndarray:
    """(H,W) pixels whose rays are rendered: those within the silhouette margin of the rasterized mesh."""
    if not raster.hit.any():
        return raster.hit
    return binary_dilation(raster.hit, iterations=silhouette_margin_px(cfg, camera, raster.depth))


class CoDyNeRFAvatar(PoseCorrected, Avatar):
    name: ClassVar[str] = "codynerf"
    quality_knobs: ClassVar[tuple[str, ...]] = ("samples", "fine", "bf16")
    config_class: ClassVar[type] = LossWeights

    def __init__(self, head_model: HeadModel, field_cfg: FieldConfig, n_frames: int, background: np.ndarray,
                 render_cfg: RenderConfig = RenderConfig(), loss_weights: LossWeights | None = None):
        super().__init__(head_model, n_frames, background)
        self.field_cfg = field_cfg
        self.render_cfg = render_cfg
        self.loss_weights = loss_weights or LossWeights()
        self.field = self.make_field()
        self.omega = nn.Embedding(n_frames, field_cfg.deform_code_dim)
        self.phi = nn.Embedding(n_frames, field_cfg.appearance_code_dim)
        nn.init.zeros_(self.omega.weight)
        nn.init.zeros_(self.phi.weight)
        template = torch.as_tensor(head_model.template, dtype=torch.float32)
        margin = render_cfg.shell_m + 0.02
        self.occupancy = OccupancyGrid(template.min(0).values - margin, template.max(0).values + margin)
        self.pose_corrections: nn.Parameter | None = None
        """(N,6) per training frame (components/poses.py); None: the poses as given."""
        self.expression_corrections: nn.Parameter | None = None  # (its guide mesh's trees are made once a frame)
        self.plate, self.views = Plate(), CaptureViews()
        """What the capture kept (components/): its background plate, where its camera stood."""
        self.code_keys = CodeKeys(head_model.num_expression)
        """The training frames' control keys: new controls take the nearest frames' codes."""

    # ---- making and describing -------------------------------------------------------------------------
    def note_views(self, frames) -> None:
        """Where the capture's camera stood, if it stood still (its colour reads the view from there)."""
        self.views.note(frames.origins, None, self.background.device)

    def make_field(self) -> CoDyNeRFField:
        """The fields of field_cfg; a tri-plane covers the template grown by the farthest reach (MAX_REACH_M)."""
        template = torch.as_tensor(self.head_model.template, dtype=torch.float32)
        margin = MAX_REACH_M + 0.02
        return CoDyNeRFField(self.field_cfg, max(self.head_model.landmarks.count, 1),
                             (template.min(0).values - margin, template.max(0).values + margin))

    @classmethod
    def for_capture(cls, head_model: HeadModel, n_frames: int, background: np.ndarray, effects: tuple[str, ...],
                    lighting: dict | None, config: LossWeights | None = None) -> CoDyNeRFAvatar:
        field_cfg = FieldConfig(effects=effects, light_dir=key_light_dir(lighting) if "shadows" in effects else None)
        return cls(head_model, field_cfg, n_frames, background, RenderConfig(), config)

    @classmethod
    def from_meta(cls, head_model: HeadModel, meta: dict) -> CoDyNeRFAvatar:
        field_cfg, render_cfg = field_config(meta), RenderConfig(**meta["render"])
        check_config(field_cfg)
        check_config(render_cfg)
        avatar = cls(head_model, field_cfg, int(meta["frames"]), np.asarray(meta["background"], np.float32),
                     render_cfg)
        avatar.restore_corrections(meta)
        return avatar

    def meta(self) -> dict:
        return {"model": self.name, "effects": list(self.field_cfg.effects), "field": asdict(self.field_cfg),
                "render": asdict(self.render_cfg), **self.corrections_meta()}

    # ---- the tracked poses, corrected ------------------------------------------------------------------
    def fit_to_tracked_video(self, corrections: bool | None = None) -> None:
        """Learn a correction of each training frame's head pose with the avatar (correct_poses; corrections: None
        or True, False: the poses as tracked); Eq. 13 shapes
        the normals only, not the density (LossWeights.consistency_shapes_density); and no Cauchy
        sparsity (Eq. 14): on the tracked d3 video (25 minutes, `none`) it held the density to a fog that let 32%
        of the light through the head (the room's plate would show through it when the head moves), against 1%
        without, at the same held-out PSNR (16.60 and 16.54 dB) and 26% less render time (the early stop ends
        rays at an opaque skin)."""
        if corrections is not False:
            self.correct_poses()
        self.loss_weights = replace(self.loss_weights, cauchy=0.0, consistency_shapes_density=False,
                                    mesh_normals_first=True)

    def pose_centre(self, geometry: FrameGeometry) -> torch.Tensor:
        """The middle of the head's box. Corrected rays keep the frame's surface distances (corrections are
        millimetres; the shell spans centimetres)."""
        return 0.5 * (geometry.box_min + geometry.box_max)

    @property
    def effects(self) -> tuple[str, ...]:
        return self.field_cfg.effects

    # ---- per frame -------------------------------------------------------------------------------------
    def geometry(self, controls: Controls, time_s: float | None = None) -> FrameGeometry:
        """The frame's meshes, tree, landmarks and box (no shadow map), and the codes' weights new controls take."""
        return replace(frame_geometry(self.head, controls, self.render_cfg.box_margin_m),
                       code_weights=self.code_keys.weights(controls, time_s))

    def frame_geometry(self, controls: Controls, rasterizer: Rasterizer | None, time_s: float | None = None
                       ) -> FrameGeometry:
        geo = self.geometry(controls, time_s)
        if not self.field_cfg.shadow_factor:
            return geo
        if rasterizer is None:
            raise ValueError("this avatar's shadow factor reads the posed mesh's shadow map: pass a rasterizer")
        return with_light_depth(geo, self.head_model.triangles, self.field_cfg.light_dir, rasterizer)

    def image_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        if self.render_cfg.dense_samples:  # the reference renders every pixel whose ray crosses the head's box
            return np.ones_like(raster.hit)
        return active_pixels(self.render_cfg, camera, raster)

    def fit_to_capture(self, foreground_reach_m: np.ndarray | None) -> None:
        """Model everything the capture's masks show of the person: the field's shell (its support about the
        mesh), the head's box and the rendered pixels reach as far beyond the mesh as the foreground goes (99.9% of
        its pixels, + 2 mm: hair, collar), between the default shell and MAX_REACH_M, with samples added to keep
        their spacing; and no farther where the capture shows nothing there."""
        if foreground_reach_m is None:
            return
        reach = float(np.quantile(foreground_reach_m, 0.999)) + 0.002 if len(foreground_reach_m) else 0.0
        rc, base = self.render_cfg, RenderConfig()
        shell = float(np.clip(reach, base.shell_m, MAX_REACH_M))
        self.render_cfg = replace(rc, silhouette_m=reach, shell_m=shell, box_margin_m=max(rc.box_margin_m, shell),
                                  samples_per_ray=self.samples_for(rc.samples_per_ray, shell))
        template = torch.as_tensor(self.head_model.template, dtype=torch.float32)
        margin = shell + 0.02
        self.occupancy = OccupancyGrid(template.min(0).values - margin, template.max(0).values + margin).to(
            self.background.device)

    @staticmethod
    def samples_for(samples: int, shell_m: float) -> int:
        """Samples a ray in a shell of half-thickness shell_m at the spacing `samples` give the default shell."""
        return max(samples, round(samples * shell_m / RenderConfig().shell_m))

    # ---- the field -------------------------------------------------------------------------------------
    def support(self, distance: torch.Tensor) -> torch.Tensor:
        """The field's support: 1 near the mesh, fading to 0 at shell_m from it, so every sampler (the shell,
        the box, the dense reference) sees the same field and nothing floats far from the head."""
        rc = self.render_cfg
        return ((rc.shell_m - distance) / (0.25 * rc.shell_m)).clamp(0.0, 1.0)

    @torch.no_grad()
    def build_occupancy(self, canonical: torch.Tensor, threshold: float = 0.5) -> float:
        """Fill the occupancy grid from the trained density about a canonical mesh (V,3) (the capture's
        identity, no expression, no pose). threshold: density (1/m) below which a cell counts as empty; at
        the shell sampler's spacing (5 mm) such a sample is at most 0.25% opaque. Returns the occupied share."""
        tree = vertex_tree(canonical)

        def density(x: torch.Tensor) -> torch.Tensor:
            idx = nearest_vertices(x, canonical, tree)
            distance = (x - canonical[idx]).norm(dim=-1)
            return self.field.canonical_density(x, distance)[0] * self.support(distance)

        return self.occupancy.build(density, threshold, generator=torch.Generator().manual_seed(0))

    def mesh_field(self, controls: Controls, rasterizer: Rasterizer | None) -> MeshField:
        """The field where rays would sample it (within the shell about the posed mesh, faded by its support), the
        codes new controls take, colours seen from in front of the face with the capture's light and shadows."""
        geo = self.frame_geometry(controls, rasterizer)
        omega, phi = self.codes(None, geo.code_weights)
        rc = self.render_cfg
        rotation = rotation_matrix_from_axis_angle(torch.as_tensor(controls.root, dtype=torch.float32)[None])[0]
        eye = front_eye(rotation.to(geo.posed.device), geo.posed.mean(0))

        def at(points: torch.Tensor, colour: bool) -> torch.Tensor:
            points = points.to(geo.posed.device)
            near, prior = prior_within(points, geo.meshes, rc.shell_m, rc.prior_falloff_m, geo.tree)
            # the density alone needs no normals: the mesh's stand in, and no gradient is taken
            out = self.field.geometry(points[near], prior, omega, mesh_normals=not colour)
            if not colour:
                return torch.zeros(len(points), device=points.device).index_copy(
                    0, near, out.sigma.detach() * self.support(prior.distance))
            view = torch.nn.functional.normalize(eye - points[near], dim=-1)
            light = geo.light.visibility(points[near]) if self.field_cfg.shadow_factor else None
            lit, factor, _ = self.field.appearance_terms(out, prior, view, phi, geo.landmarks, light)
            rgb = (lit if factor is None else lit * factor).detach()
            return torch.zeros(len(points), 3, device=points.device).index_copy(0, near, rgb)

        return MeshField(geo.box_min.cpu().numpy(), geo.box_max.cpu().numpy(), lambda p: at(p, False),
                         lambda p: at(p, True))

    def codes(self, frame: int | None, weights: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """omega and phi (1,C) of a training frame; for new controls (frame None) the training frames' codes
        blended by `weights` (N,) (Avatar.code_weights), or without them the mean codes."""
        return frame_code(self.omega, frame, weights), frame_code(self.phi, frame, weights)

    # ---- rays ------------------------------------------------------------------------------------------
    def settings(self, training: bool, create_graph: bool = False, quality: Quality | None = None
                 ) -> render.RaySettings:
        """The exact path for training; display's shortcuts from the render config, its samples from `quality`
        (a preset's) where given."""
        rc = self.render_cfg if quality is None else self.with_quality(quality)
        if training or rc.dense_samples:
            return render.RaySettings(rc.samples_per_ray, rc.shell_m, dense=0 if training else rc.dense_samples,
                                      create_graph=create_graph)
        return render.RaySettings(rc.samples_per_ray, rc.shell_m, fine=rc.fine_samples, stop_below=rc.stop_below,
                                  min_weight=rc.min_weight, skip_empty=rc.occupancy)

    def render_rays(self, rays: Rays, geometry: FrameGeometry, frame: int | None,
                    generator: torch.Generator | None = None, training: bool = False, options: Any = None,
                    create_graph: bool = False, mesh_normals: bool = False) -> RayOutput:
        """Colour, opacity, depth (and, with normals, predicted and density-gradient normals) of R rays: every
        buffer whatever the options ask. create_graph: keep the density gradients' graph (training through the
        normals, Eq. 13). mesh_normals: the mesh's normals stand in for both (RaySettings.mesh_normals). options:
        render_image's; its quality (a preset's samples) where given."""
        omega, phi = self.codes(frame, geometry.code_weights)
        if not training:
            omega, phi = omega.detach(), phi.detach()
        if self.pose_corrections is not None and frame is not None:
            rays = self.corrected_rays(rays, geometry, frame)
        quality = None if training or options is None else options.quality
        settings = replace(self.settings(training, create_graph, quality), mesh_normals=mesh_normals)
        return self.trace(rays, geometry, omega, phi, settings, generator)

    def trace(self, rays: Rays, geo: FrameGeometry, omega: torch.Tensor, phi: torch.Tensor,
              settings: render.RaySettings, generator: torch.Generator | None = None) -> RayOutput:
        """render_rays with given codes (1,C) and settings: sample, evaluate the density, (a fine pass),
        colour the samples that show, composite."""
        assert omega.shape[0] == 1 and phi.shape[0] == 1, "one code per batch of rays (a frame's, or the mean)"
        samples = render.sample_rays(rays, geo.box_min, geo.box_max, settings, generator)
        pts, d, sigma, weights, remaining = self._densities(rays, geo, omega, samples, settings)
        if settings.fine > 0:
            samples = fine_samples(samples, weights.detach(), settings.fine, generator)
            pts, d, sigma, weights, remaining = self._densities(rays, geo, omega, samples,
                                                                replace(settings, stop_below=0))
        shown = render.shown_samples(d, weights, rays.directions, settings.min_weight)
        fixed_view = self.views.towards_camera(pts[shown.keep])  # a tracked video's view
        shown = shown if fixed_view is None else replace(shown, view=fixed_view)
        mesh_vis = geo.light.visibility(pts[shown.keep]) if self.field_cfg.shadow_factor else None
        lit, factor, visibility = self.field.appearance_terms(shown.field, shown.prior, shown.view, phi,
                                                              geo.landmarks, mesh_vis)
        lit = shown.to_rays(lit)
        factor = None if factor is None else shown.to_rays(factor)
        background = self.ray_background(rays)
        internals = render.CoDyNeRFRays(samples, d, sigma, weights, remaining, shown, phi, mesh_vis, lit, factor,
                                        visibility, background)
        colour = lit * (1.0 if factor is None else factor)
        R, S = weights.shape
        buffers = {"rgb": composite(weights, colour, remaining, background), "opacity": weights.sum(-1),
                   "depth": expected_depth(weights, samples.t_mid)}
        if d.field.normal is not None:
            pn = render.scatter(d.field.normal, d.keep, R * S).reshape(R, S, 3)
            pg = render.scatter(d.field.grad_normal, d.keep, R * S).reshape(R, S, 3)
            internals.point_normal, internals.point_grad_normal = pn, pg
            buffers["normals"], buffers["grad_normals"] = composite(weights, pn), composite(weights, pg)
        return RayOutput(buffers, internals)

    def _densities(self, rays: Rays, geo: FrameGeometry, omega: torch.Tensor, samples: render.RaySamples,
                   settings: render.RaySettings):
        """The samples' points (R*S,3), the field there (all, or with the early stop), sigma (R,S), the compositing
        weights (R,S) and the light left (R,)."""
        pts = render.sample_points(rays, samples)
        S = samples.t_starts.shape[1]
        valid = samples.valid.repeat_interleave(S)
        occupied = self.occupancy.lookup if settings.skip_empty else None
        rc = self.render_cfg

        def evaluate(idx: torch.Tensor) -> render.Densities:
            """Prior and geometry at flat sample indices; samples outside the field's support are not evaluated
            at all (exactly: their density is zero)."""
            near, prior_in = prior_within(pts[idx], geo.meshes, rc.shell_m, rc.prior_falloff_m, geo.tree)
            support = self.support(prior_in.distance) * valid[idx[near]]
            inside = torch.nonzero(support > 0).squeeze(1)
            prior_in = prior_in.take(inside) if len(inside) < len(near) else prior_in
            keep = idx[near[inside]]
            out = self.field.geometry(pts[keep], prior_in, omega, settings.create_graph, occupied,
                                      settings.mesh_normals)
            return render.Densities(keep, prior_in, out, support[inside])

        d = render.densities_early_stop(evaluate, samples, settings.stop_below)
        return (pts, d, *render.weights_of(d, samples))

    def loss_terms(self, batch: TrainingBatch) -> dict[str, torch.Tensor]:
        """The losses of Eq. 9-14 (and the shadow factor's) on one frame's rays, weighted."""
        w = self.loss_weights
        consistency = consistency_weight(w, batch.progress)
        # Second derivatives only while Eq. 13 ties density gradients to the normals: before that the density
        # gradient is an input the normals network reads, not something to train through.
        second_order = self.field_cfg.needs_normals and consistency > 0 and w.consistency_shapes_density
        mesh_normals = w.mesh_normals_first and batch.progress < w.consistency_start
        out = self.render_rays(batch.rays, batch.geometry, batch.frame, batch.generator, training=True,
                               create_graph=second_order, mesh_normals=mesh_normals)
        parts = ray_terms(w, out.internals, out.buffers["rgb"], batch.target, batch.rays.directions,
                          batch.progress, self.codes(batch.frame))
        if out.internals.point_normal is not None and not mesh_normals:
            parts["mesh_normals"] = w.mesh_normals * self.mesh_normal_term(batch, second_order)
        if self.pose_corrections is not None:
            parts["pose_corrections"] = w.pose_corrections * self.pose_correction_term(batch.frame)
        return parts

    def mesh_normal_term(self, batch: TrainingBatch, second_order: bool) -> torch.Tensor:
        """Eq. 9 on a random subset of the frame's posed vertices (DistToMesh = 0 there)."""
        geo = batch.geometry
        n = self.loss_weights.mesh_normal_vertices
        idx = torch.randint(len(geo.meshes.posed), (n,), generator=batch.generator).to(geo.meshes.posed.device)
        pts = geo.meshes.posed[idx]
        prior = deformation_prior(pts, geo.meshes, self.render_cfg.prior_falloff_m, geo.tree)
        omega, _ = self.codes(batch.frame)
        out = self.field.geometry(pts, prior, omega.expand(n, -1), create_graph=second_order)
        return losses.mesh_normal_consistency(out.normal, geo.meshes.normals[idx])

    # ---- inspection ------------------------------------------------------------------------------------
    @classmethod
    def buffer_names(cls, meta: dict) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """With normals, the predicted and the density-gradient normals; to inspect, the render without cast
        shadows (for an avatar without a shadow factor: with the neutral head's shadow inputs), the key light's
        visibility (with a factor), and the render with every normal turned to the viewer (with normals)."""
        cfg = field_config(meta)
        shadows = ("rgb_no_shadows", "rgb_light") if cfg.shadow_factor else ("rgb_no_shadows",)
        normals = cfg.needs_normals
        return ("normals", "grad_normals") if normals else (), \
            (shadows if "shadows" in cfg.effects else ()) + (("rgb_flat",) if normals else ())

    def inspect(self, out: RayOutput, geometry: FrameGeometry, names: tuple[str, ...]) -> dict[str, torch.Tensor]:
        r: render.CoDyNeRFRays = out.internals
        unknown = set(names) - set(self.inspection_buffers())
        if unknown:
            raise ValueError(f"this avatar (effects: {self.describe_effects()}) has no buffers {sorted(unknown)}")
        result = {}
        for name in names:
            if name == "rgb_no_shadows" and r.factor is not None:  # the shadow factor at 1: lit everywhere
                result[name] = composite(r.weights, r.lit, r.remaining, r.background)
            elif name == "rgb_no_shadows":  # no factor: the neutral head's shadow inputs, no expression or pose
                zero = torch.zeros_like(r.shown.prior.offset)
                neutral = replace(r.shown.prior, expression_offset=zero, pose_offset=zero)
                result[name] = composite(r.weights, self._colour(r, r.shown.field, neutral,
                                                                 geometry.neutral_landmarks),
                                         r.remaining, r.background)
            elif name == "rgb_light":  # the key light's visibility (1: no cast shadow), grey
                light = composite(r.weights, r.shown.to_rays(r.visibility), r.remaining, r.visibility.new_ones(1))
                result[name] = light.expand(len(r.weights), 3)
            elif name == "rgb_flat":  # every surface facing the viewer: the shading's contribution is what changes
                flat = replace(r.shown.field, normal=r.shown.view)
                result[name] = composite(r.weights, self._colour(r, flat, r.shown.prior, geometry.landmarks),
                                         r.remaining, r.background)
        return result

    def _colour(self, r: render.CoDyNeRFRays, field_out, prior, landmarks: torch.Tensor) -> torch.Tensor:
        """(R,S,3) the colour of the shown samples under other appearance inputs."""
        colour = self.field.appearance(field_out, prior, r.shown.view, r.phi, landmarks, r.mesh_visibility)
        return r.shown.to_rays(colour)

    def layout(self) -> dict[str, tuple[int, float | str]]:
        return super().layout() | {"normals": (3, 0.0), "grad_normals": (3, 0.0), "rgb_no_shadows": (3, BACKGROUND),
                                   "rgb_light": (3, 1.0), "rgb_flat": (3, BACKGROUND)}

    def display_mode(self, options: Any = None) -> contextlib.AbstractContextManager:
        """No gradients, except that density-gradient normals need autograd (no_grad, not inference_mode);
        bf16 where the options' quality (else the render config) says."""
        bf16 = self.render_cfg.bf16 if options is None or options.quality is None else options.quality.bf16
        stack = contextlib.ExitStack()
        stack.enter_context(torch.no_grad() if self.field_cfg.needs_normals else torch.inference_mode())
        stack.enter_context(torch.autocast(self.background.device.type, torch.bfloat16, enabled=bf16))
        return stack

    @property
    def chunk_rays(self) -> int:
        return self.render_cfg.chunk_rays

    # ---- settings and lifecycle ------------------------------------------------------------------------
    def with_quality(self, quality: Quality) -> RenderConfig:
        """The render config with a quality setting's samples (at the spacing they give the default shell), second
        pass and bf16."""
        return replace(self.render_cfg, samples_per_ray=self.samples_for(quality.samples, self.render_cfg.shell_m),
                       fine_samples=quality.fine, bf16=quality.bf16)

    def before_save(self, geometry: FrameGeometry) -> None:
        """The display's occupancy grid follows the density: rebuilt with every checkpoint."""
        self.build_occupancy(geometry.meshes.canonical)


def field_config(meta: dict) -> FieldConfig:
    """The field's sizes from avatar.json (avatars written before the shadow factor existed have no light_dir)."""
    f = meta["field"]
    light = f.get("light_dir")
    if light is not None:
        light = np.asarray(light, np.float64)
        if light.shape != (3,) or not np.isfinite(light).all() or np.linalg.norm(light) < 1e-9:
            raise ValueError(f"field light_dir {f['light_dir']}: not a direction (three finite numbers, not all 0)")
        light = tuple(float(v) for v in light / np.linalg.norm(light))
    return FieldConfig(**{**f, "effects": tuple(f["effects"]), "light_dir": light})
