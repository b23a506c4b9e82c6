"""The avatar (DESIGN 3): a head model, the CoDyNeRF fields and per-frame codes, rendered along rays.

Rendering a frame: the posed mesh is rasterized (GL) for the distance to its surface along each pixel's ray;
rays near the head's silhouette sample a shell about the surface (or the head's box where they miss the
mesh), every other pixel is background. Samples take the 3DMM prior (Eq. 3-4), the fields (Eq. 2, 5, 7, 8),
and are composited over the background (Eq. 1).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

import numpy as np
import torch
from pykdtree.kdtree import KDTree
from scipy.ndimage import binary_dilation, distance_transform_edt
from torch import nn

from models.fields.codynerf import CoDyNeRFField, FieldConfig, FieldOutput
from models.fields.mesh_light import MeshLight, mesh_light
from models.fields.occupancy import OccupancyGrid
from models.fields.prior import PriorMeshes, PriorSamples, nearest_vertices, prior_within, vertex_tree
from models.head.controls import Controls
from models.head.head import Head
from models.head.model import HeadModel
from render.camera import Camera
from render.gl.raster import Raster, Rasterizer, pixel_rays, surface_distance
from render.mesh import vertex_normals
from render.sampling import RaySamples, shell_or_box_samples
from render.volume import composite, expected_depth, sample_pdf, weights_from_density


@dataclass(frozen=True)
class RenderConfig:
    """How many samples, where. Lengths in metres."""

    samples_per_ray: int = 12
    """Samples in the shell about the surface (or across the box for rays that miss the mesh)."""
    shell_m: float = 0.03
    """Half-thickness of the shell about the rasterized surface."""
    box_margin_m: float = 0.03
    """The head's box: the posed mesh's bounds grown by this much."""
    silhouette_px: int = 3
    silhouette_m: float | None = None
    """How far the capture's foreground reaches beyond the mesh's silhouette (hair, shoulders), metres,
    measured from the capture's masks when training starts; None (no masks): the whole shell."""
    """Rays within this many pixels of the mesh's silhouette are rendered (at least as many as the shell
    spans at the head's distance); farther ones are background."""
    prior_falloff_m: float = 0.05
    """Length over which the 3DMM prior fades with distance from the mesh."""
    stop_below: float = 1e-3
    """Display ends a ray early once less than this share of the light gets through its front half."""
    occupancy: bool = False
    """Display skips the density network where the occupancy grid says the canonical point is empty. Off:
    measured on the 25-minute ICT sun avatar (all effects), it cost 4-6 dB PSNR on test frames (likely cause,
    not proven: 4 random points per 5 mm cell miss a sharp surface's thin shell); an earlier, cheaper lookup
    saved 8% of the time (149 to 137 ms at 128 px, `none`)."""
    bf16: bool = False
    """Display runs the networks in bfloat16 (training is always float32)."""
    fine_samples: int = 0
    """Display: a second pass adds this many samples where the first pass's weights lie (0: one pass)."""
    min_weight: float = 1e-4
    """Display skips the colour of samples that add less than this to their pixel (training never does)."""
    chunk_rays: int = 4096
    """Rays per batch when rendering an image (memory)."""


@dataclass
class FrameGeometry:
    """Everything about one frame's head that the rays need: meshes, k-d tree, landmarks, box."""

    meshes: PriorMeshes
    tree: KDTree
    landmarks: torch.Tensor  # (1, 3L) relative to the landmarks' centre
    box_min: torch.Tensor  # (3,)
    box_max: torch.Tensor  # (3,)
    light: MeshLight | None = None  # the posed mesh's shadow map, for avatars whose shadow factor reads it

    def to(self, device: torch.device | str) -> FrameGeometry:
        """The same geometry with its tensors on `device` (the k-d tree stays on the CPU)."""
        m = self.meshes
        return FrameGeometry(PriorMeshes(*(t.to(device) for t in (m.canonical, m.expressed, m.posed, m.normals))),
                             self.tree, self.landmarks.to(device), self.box_min.to(device), self.box_max.to(device),
                             None if self.light is None else self.light.to(device))


@dataclass
class RayOutput:
    rgb: torch.Tensor  # (R,3)
    opacity: torch.Tensor  # (R,)
    depth: torch.Tensor  # (R,)
    normal: torch.Tensor | None  # (R,3) composited predicted normals
    grad_normal: torch.Tensor | None  # (R,3) composited density-gradient normals
    weights: torch.Tensor  # (R,S)
    sigma: torch.Tensor  # (R,S)
    samples: RaySamples
    point_normal: torch.Tensor | None = None  # (R,S,3)
    point_grad_normal: torch.Tensor | None = None  # (R,S,3)
    variants: dict[str, torch.Tensor] = field(default_factory=dict)  # name -> (R,3) colour under other inputs
    point_factor: torch.Tensor | None = None  # (R,S) share of each sample's lit colour the cast shadows leave (F)


def silhouette_margin_px(cfg: RenderConfig, camera: Camera, depth: np.ndarray) -> int:
    """Pixels around the mesh's silhouette to render: how far the capture's foreground reaches beyond the
    mesh (cfg.silhouette_m; else the shell, as density lives within shell_m of the mesh) at the nearest
    surface's distance, at least cfg.silhouette_px."""
    finite = depth[np.isfinite(depth)]
    if len(finite) == 0:
        return cfg.silhouette_px
    reach = cfg.shell_m if cfg.silhouette_m is None else min(cfg.silhouette_m, cfg.shell_m)
    return max(cfg.silhouette_px, int(np.ceil(reach * camera.focal_px() / max(finite.min(), 1e-3))))


def foreground_reach_m(hit: np.ndarray, depth: np.ndarray, mask: np.ndarray, focal_px: float) -> np.ndarray:
    """For each foreground pixel of a capture's mask outside the mesh's silhouette, how far (metres, at the
    nearest mesh pixel's depth) it lies from the silhouette: what the avatar must render beyond the mesh."""
    outside = (mask > 0.5) & ~hit
    if not outside.any() or not hit.any():
        return np.zeros(0, np.float32)
    dist_px, (ii, jj) = distance_transform_edt(~hit, return_indices=True)
    return (dist_px * depth[ii, jj] / focal_px)[outside].astype(np.float32)


def active_pixels(cfg: RenderConfig, camera: Camera, raster: Raster) -> np.ndarray:
    """(H,W) pixels whose rays are rendered: those within the silhouette margin of the rasterized mesh."""
    if not raster.hit.any():
        return raster.hit
    return binary_dilation(raster.hit, iterations=silhouette_margin_px(cfg, camera, raster.depth))


def fine_samples(samples: RaySamples, weights: torch.Tensor, n: int, generator: torch.Generator | None = None
                 ) -> RaySamples:
    """The first pass's samples plus n drawn where its weights (R,S) lie, as intervals about the sorted
    sample points, within the first pass's span."""
    edges = torch.cat([samples.t_starts, samples.t_ends[:, -1:]], 1)
    t_all = torch.sort(torch.cat([samples.t_mid, sample_pdf(edges, weights, n, generator)], 1), 1).values
    mids = 0.5 * (t_all[:, 1:] + t_all[:, :-1])
    return RaySamples(torch.cat([samples.t_starts[:, :1], mids], 1), torch.cat([mids, samples.t_ends[:, -1:]], 1),
                      samples.valid)


def per_sample(code: torch.Tensor, S: int) -> Callable[[torch.Tensor], torch.Tensor]:
    """For a code per ray (R,C), the codes of flat sample indices (each ray's S samples share its code); one
    code for all rays (1,C) stays (1,C), which the networks fold into a bias instead of copying it."""
    if code.shape[0] == 1:
        return lambda idx: code
    return lambda idx: code[torch.div(idx, S, rounding_mode="floor")]


def mean_code(embedding: nn.Embedding) -> torch.Tensor:
    return embedding.weight.mean(0, keepdim=True)


def concat_outputs(outputs: list[FieldOutput]) -> FieldOutput:
    """FieldOutputs of disjoint sample sets, one after the other."""
    if len(outputs) == 1:
        return outputs[0]
    cat = lambda name: None if getattr(outputs[0], name) is None else torch.cat([getattr(o, name) for o in outputs])
    return FieldOutput(*(cat(f.name) for f in fields(FieldOutput)))


class RenderCancelled(Exception):
    """A render stopped part-way because a newer request replaced it."""


def image_rays(camera: Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """The camera's origin (1,3) and its pixels' unit ray directions (H*W,3), rows top first."""
    origin, dirs = pixel_rays(camera)
    return torch.as_tensor(origin, dtype=torch.float32)[None], torch.as_tensor(dirs.reshape(-1, 3), dtype=torch.float32)


def scatter_rays(parts: dict[str, list[torch.Tensor]], camera: Camera, idx: np.ndarray, background: np.ndarray
                 ) -> dict[str, np.ndarray]:
    """Images (H,W,...) from per-ray results computed in chunks for the flat pixel indices `idx`; pixels not
    rendered are background (rgb), 0 (opacity, normals) or inf (depth)."""
    H, W = camera.height_px, camera.width_px
    fill = {"rgb": background, "rgb_no_shadows": background, "rgb_flat": background, "rgb_light": 1.0, "depth": np.inf}
    out = {}
    for k, chunks in parts.items():
        values = torch.cat(chunks).float().cpu().numpy() if chunks else np.zeros((0,), np.float32)
        channels = () if k in ("opacity", "depth") else (3,)
        img = np.zeros((H * W, *channels), np.float32)
        img[:] = fill.get(k, 0.0)
        if len(idx):
            img[idx] = values.reshape(len(idx), *channels)
        out[k] = img.reshape(H, W, *channels)
    return out


class Avatar(nn.Module):
    def __init__(self, head_model: HeadModel, field_cfg: FieldConfig, n_frames: int, background: np.ndarray,
                 render_cfg: RenderConfig = RenderConfig()):
        super().__init__()
        self.head_model = head_model
        self.head = Head(head_model)
        self.field_cfg = field_cfg
        self.render_cfg = render_cfg
        self.field = CoDyNeRFField(field_cfg, max(head_model.landmarks.count, 1))
        self.omega = nn.Embedding(n_frames, field_cfg.deform_code_dim)
        self.phi = nn.Embedding(n_frames, field_cfg.appearance_code_dim)
        nn.init.zeros_(self.omega.weight)
        nn.init.zeros_(self.phi.weight)
        self.register_buffer("background", torch.as_tensor(np.asarray(background, np.float32)))
        template = torch.as_tensor(head_model.template, dtype=torch.float32)
        margin = render_cfg.shell_m + 0.02
        self.occupancy = OccupancyGrid(template.min(0).values - margin, template.max(0).values + margin)

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

    # ---- geometry --------------------------------------------------------------------------------------
    def with_light(self, geo: FrameGeometry, rasterizer: Rasterizer) -> FrameGeometry:
        """The geometry with its shadow map where this avatar's shadow factor reads one (else unchanged)."""
        if not self.field_cfg.shadow_factor:
            return geo
        light = mesh_light(geo.meshes.posed.cpu().numpy(), self.head_model.triangles, self.field_cfg.light_dir,
                           rasterizer)
        return replace(geo, light=light.to(geo.meshes.posed.device))

    @torch.no_grad()
    def geometry(self, controls: Controls) -> FrameGeometry:
        """The frame's canonical, expressed and posed meshes (DESIGN 3, step 1)."""
        neutral = Controls(shape=controls.shape)
        unposed = Controls(shape=controls.shape, expression=controls.expression)
        v, _, lm = self.head.pose([neutral, unposed, controls])
        posed = v[2]
        normals = torch.as_tensor(vertex_normals(posed.cpu().numpy(), self.head_model.triangles)).to(posed.device)
        m = self.render_cfg.box_margin_m
        lm_rel = lm[2] - lm[2].mean(0) if lm.shape[1] else torch.zeros(1, 3, device=posed.device)
        return FrameGeometry(PriorMeshes(v[0], v[1], posed, normals), vertex_tree(posed), lm_rel.reshape(1, -1),
                             posed.min(0).values - m, posed.max(0).values + m)

    # ---- rays ------------------------------------------------------------------------------------------
    def render_rays(
        self,
        origins: torch.Tensor,  # (R,3)
        directions: torch.Tensor,  # (R,3) unit
        surface_t: torch.Tensor,  # (R,) inf where the ray misses the mesh
        geo: FrameGeometry,
        omega: torch.Tensor,  # (1,C) or (R,C)
        phi: torch.Tensor,  # (1,C) or (R,C)
        generator: torch.Generator | None = None,
        create_graph: bool = False,
        dense_samples: int | None = None,
        min_weight: float = 0.0,
        skip_empty: bool = False,
        stop_below: float = 0.0,
        fine: int = 0,
        samples: RaySamples | None = None,
        variants: tuple[str, ...] = (),
        neutral_landmarks: torch.Tensor | None = None,
    ) -> RayOutput:
        """Composited colour, opacity, depth (and normals) of R rays. dense_samples: ignore the mesh and
        spread that many samples over the head's box instead (the slow reference the shell sampler is
        checked against). Display only: min_weight skips the colour of samples that add less than that to
        their pixel; skip_empty consults the occupancy grid; stop_below ends rays early (the front half of
        every ray first, the back half only where more than stop_below of the light gets through). fine: a
        second pass adds that many samples where the first pass's weights lie (inverse-transform sampling of
        its weights) and renders all of them; samples: the intervals to use instead of the sampler's.
        variants: colours of the same samples under other appearance inputs, for inspection: "no_shadows" (the
        shadow factor at 1; an avatar without the factor: the shadow inputs of the neutral head,
        `neutral_landmarks`, and no expression or pose offsets), "light" (the key light's visibility S
        composited, grey, 1 where nothing is in the way) and "flat" (every normal turned to the viewer)."""
        rc = self.render_cfg
        if dense_samples:
            surface_t = torch.full_like(surface_t, float("inf"))
        if samples is None:
            samples = shell_or_box_samples(origins, directions, surface_t, geo.box_min, geo.box_max,
                                           dense_samples or rc.samples_per_ray, rc.shell_m, generator)
        R, S = samples.t_starts.shape
        pts = (origins[:, None] + directions[:, None] * samples.t_mid[..., None]).reshape(-1, 3)
        valid = samples.valid.repeat_interleave(S)
        omega_s = per_sample(omega, S)
        occupied = self.occupancy.lookup if skip_empty else None

        def evaluate(idx: torch.Tensor) -> tuple[torch.Tensor, PriorSamples, FieldOutput, torch.Tensor]:
            """Prior and geometry at flat sample indices. Samples outside the field's support are not
            evaluated at all (exactly: their density is zero)."""
            near, prior_in = prior_within(pts[idx], geo.meshes, rc.shell_m, rc.prior_falloff_m, geo.tree)
            support = self.support(prior_in.distance) * valid[idx[near]]
            inside = torch.nonzero(support > 0).squeeze(1)
            prior_in = prior_in.take(inside) if len(inside) < len(near) else prior_in
            keep = idx[near[inside]]
            return keep, prior_in, self.field.geometry(pts[keep], prior_in, omega_s(keep), create_graph,
                                                       occupied), support[inside]

        flat = torch.arange(R * S, device=pts.device).reshape(R, S)
        if stop_below > 0 and S > 2:
            front = S // 2 + 1
            first = evaluate(flat[:, :front].reshape(-1))
            sigma_front = first[3].new_zeros(R * S).index_copy(0, first[0], first[2].sigma * first[3])
            optical = (sigma_front.reshape(R, S)[:, :front] * samples.deltas[:, :front]).sum(-1)
            lit = torch.exp(-optical) > stop_below
            parts = [first, evaluate(flat[lit, front:].reshape(-1))]
        else:
            parts = [evaluate(flat.reshape(-1))]
        keep = torch.cat([p[0] for p in parts])
        prior_k = PriorSamples(*(torch.cat([getattr(p[1], f.name) for p in parts]) for f in fields(PriorSamples)))
        g = concat_outputs([p[2] for p in parts])
        support_k = torch.cat([p[3] for p in parts])
        scatter = lambda values: values.new_zeros(R * S, *values.shape[1:]).index_copy(0, keep, values)
        sigma = scatter(g.sigma * support_k).reshape(R, S)
        weights, remaining = weights_from_density(sigma, samples.deltas)
        if fine > 0:
            union = fine_samples(samples, weights.detach(), fine, generator)
            return self.render_rays(origins, directions, surface_t, geo, omega, phi, generator, create_graph,
                                    min_weight=min_weight, skip_empty=skip_empty, samples=union, variants=variants,
                                    neutral_landmarks=neutral_landmarks)
        # Colour where a sample shows (display may skip samples that add less than min_weight to a pixel).
        shown = torch.nonzero(weights.reshape(-1)[keep] > min_weight).squeeze(1) if min_weight > 0 else None
        view = (-directions[:, None]).expand(R, S, 3).reshape(-1, 3)[keep]
        phi_at = per_sample(phi, S)
        if shown is None:  # every sample (training): no subset copies
            g_shown, prior_shown, view_shown, keep_shown = g, prior_k, view, keep
        else:
            g_shown = FieldOutput(g.sigma[shown], g.rgb[shown], g.x_canonical[shown],
                                  None if g.normal is None else g.normal[shown])
            prior_shown, view_shown, keep_shown = prior_k.take(shown), view[shown], keep[shown]

        def to_rays(values: torch.Tensor) -> torch.Tensor:
            """Values (N,C) of the shown samples -> (R,S,C), zero at the others."""
            if shown is not None:
                values = values.new_zeros(len(keep), values.shape[1]).index_copy(0, shown, values)
            return scatter(values).reshape(R, S, -1)

        mesh_vis = geo.light.visibility(pts[keep_shown]) if self.field_cfg.shadow_factor else None

        def colour(g_in: FieldOutput, prior_in: PriorSamples, landmarks: torch.Tensor) -> torch.Tensor:
            return to_rays(self.field.appearance(g_in, prior_in, view_shown, phi_at(keep_shown), landmarks,
                                                 mesh_vis))

        lit, factor, visibility = self.field.appearance_terms(g_shown, prior_shown, view_shown, phi_at(keep_shown),
                                                              geo.landmarks, mesh_vis)
        point_factor = None if factor is None else to_rays(factor)
        rgb = composite(weights, to_rays(lit) * (1.0 if point_factor is None else point_factor), remaining,
                        self.background)
        extra = {}
        for name in variants:
            if name == "no_shadows" and point_factor is not None:  # the shadow factor at 1: lit everywhere
                extra[name] = composite(weights, to_rays(lit), remaining, self.background)
            elif name == "no_shadows":  # no factor: the shadow inputs of the neutral head (no expression, no pose)
                zero = torch.zeros_like(prior_shown.offset)
                p_neutral = replace(prior_shown, expression_offset=zero, pose_offset=zero)
                extra[name] = composite(weights, colour(g_shown, p_neutral, neutral_landmarks), remaining,
                                        self.background)
            elif name == "light":  # the key light's visibility (1: no cast shadow), grey
                extra[name] = composite(weights, to_rays(visibility), remaining, visibility.new_ones(1)).expand(R, 3)
            elif name == "flat":  # every surface facing the viewer: the shading's contribution is what changes
                g_flat = replace(g_shown, normal=view_shown)
                extra[name] = composite(weights, colour(g_flat, prior_shown, geo.landmarks), remaining,
                                        self.background)
        normal = grad_normal = pn = pg = None
        if g.normal is not None:
            pn, pg = scatter(g.normal).reshape(R, S, 3), scatter(g.grad_normal).reshape(R, S, 3)
            normal, grad_normal = composite(weights, pn), composite(weights, pg)
        return RayOutput(rgb, weights.sum(-1), expected_depth(weights, samples.t_mid), normal, grad_normal, weights,
                         sigma, samples, pn, pg, extra, None if point_factor is None else point_factor[..., 0])

    def inspection_variants(self) -> tuple[str, ...]:
        """The colour variants this avatar's effects make meaningful (see render_rays)."""
        shadows = ("no_shadows", "light") if self.field.shadow_net is not None else ("no_shadows",)
        return (shadows if "shadows" in self.field_cfg.effects else ()) + (
            ("flat",) if self.field_cfg.needs_normals else ())

    # ---- images ----------------------------------------------------------------------------------------
    def render_image(self, controls: Controls, camera: Camera, rasterizer: Rasterizer,
                     frame: int | None = None, dense_samples: int | None = None,
                     should_stop: Callable[[], bool] | None = None, inspect: bool = False) -> dict[str, np.ndarray]:
        """RGB, opacity, depth and (with normals) predicted and density-gradient normal maps, (H,W,...).
        `frame` picks a training frame's codes; None uses the mean code (novel controls). `should_stop` is
        asked between batches of rays; when it says yes, RenderCancelled is raised (a newer request won).
        `inspect` adds, for avatars with those effects, "rgb_no_shadows" (the colour without cast shadows; for
        an avatar without a shadow factor, with the shadow inputs of the neutral head), "rgb_light" (the key
        light's visibility, grey) and "rgb_flat" (with every normal turned to the viewer),
        from which the viewport shows the cast shadows and the shading's contribution."""
        geo = self.with_light(self.geometry(controls), rasterizer)
        raster = rasterizer.rasterize(geo.meshes.posed.cpu().numpy(), self.head_model.triangles, camera)
        origin, dirs = image_rays(camera)
        cos_view = (dirs.numpy() @ -np.linalg.inv(camera.view)[:3, 2]).reshape(raster.hit.shape)
        surface_t = surface_distance(raster, cos_view)
        # The dense reference renders every pixel whose ray crosses the head's box.
        active = np.ones_like(raster.hit) if dense_samples else active_pixels(self.render_cfg, camera, raster)
        idx = np.nonzero(active.ravel())[0]
        omega = self.omega.weight[frame:frame + 1] if frame is not None else mean_code(self.omega)
        phi = self.phi.weight[frame:frame + 1] if frame is not None else mean_code(self.phi)
        device = self.background.device
        origin, d_all = origin.to(device), dirs[idx].to(device)
        s_all = torch.as_tensor(surface_t.ravel()[idx], dtype=torch.float32).to(device)
        parts: dict[str, list[torch.Tensor]] = {"rgb": [], "opacity": [], "depth": []}
        if self.field_cfg.needs_normals:
            parts |= {"normals": [], "grad_normals": []}
        variants = self.inspection_variants() if inspect and not dense_samples else ()
        counterfactual = "no_shadows" in variants and self.field.shadow_net is None
        neutral_landmarks = self.geometry(Controls(shape=controls.shape)).landmarks if counterfactual \
            else None
        for v in variants:
            parts[f"rgb_{v}"] = []
        grad_mode = torch.no_grad() if self.field_cfg.needs_normals else torch.inference_mode()
        with grad_mode, torch.autocast(d_all.device.type, torch.bfloat16, enabled=self.render_cfg.bf16):
            for a in range(0, len(idx), self.render_cfg.chunk_rays):
                if should_stop is not None and should_stop():
                    raise RenderCancelled
                d, s = d_all[a:a + self.render_cfg.chunk_rays], s_all[a:a + self.render_cfg.chunk_rays]
                r = self.render_rays(origin.expand(len(d), 3), d, s, geo, omega.detach(), phi.detach(),
                                     dense_samples=dense_samples, min_weight=self.render_cfg.min_weight,
                                     skip_empty=self.render_cfg.occupancy and not dense_samples,
                                     stop_below=0.0 if dense_samples else self.render_cfg.stop_below,
                                     fine=0 if dense_samples else self.render_cfg.fine_samples,
                                     variants=variants, neutral_landmarks=neutral_landmarks)
                parts["rgb"].append(r.rgb)
                for v in variants:
                    parts[f"rgb_{v}"].append(r.variants[v])
                parts["opacity"].append(r.opacity)
                parts["depth"].append(torch.where(r.opacity > 0.5, r.depth, torch.full_like(r.depth, np.inf)))
                if r.normal is not None:
                    parts["normals"].append(r.normal.detach())
                    parts["grad_normals"].append(r.grad_normal.detach())
        return scatter_rays(parts, camera, idx, self.background.cpu().numpy())
