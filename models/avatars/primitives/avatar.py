"""The volumetric-primitives avatar (Cao et al. 2022 Section 3.1, after MVP, Lombardi et al. 2021), behind the avatar
interface: `train --model primitives`.

Per frame: the head model's controls pose the guide mesh; the primitives take their places on it (layout.py: a
K x K chart, each on its surface point, turned to the surface); the decoder (decoder.py) turns the frame's
condition (expression and jaw/neck rotations, a per-frame code, the view direction in the head's frame; gaze apart)
into each primitive's opacity and colour grid and its offsets, once; rays are marched through the primitives they
meet (march.py). Display caches the decode on the frame's geometry, so a frame's many batches of rays decode once.

Losses (MVP's, those that apply here): photometric (squared error, as the other models), the volume prior (the
primitives' summed volume, relative to where they started: keeps them tight, so empty space costs nothing), the
offsets' L2 (primitives stay near their places on the mesh), and the per-frame codes' L2; on a tracked video the
face's depth (face_depth: the face's light held within face_margin_m of the tracked mesh), and with `train
--corrections` the per-frame pose and expression corrections' priors (components/poses.py).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
from typing import Annotated, ClassVar

import numpy as np
import torch
import torch.nn.functional as F
from scipy.ndimage import binary_dilation
from torch import nn

from models.avatars.base import BACKGROUND, Avatar, RayOutput, TrainingBatch
from models.avatars.components import losses
from models.avatars.components.body import BODY_LR_SCALE, BodyLayer, body_frame
from models.avatars.components.codes import GAZE_KEYS, CodeKeys, frame_code, left_out_weights
from models.avatars.components.plate import Plate
from models.avatars.components.poses import PoseCorrected
from models.avatars.components.rigid import head_pose, head_turn, turned_on_body
from models.avatars.components.views import CaptureViews
from models.avatars.effects import key_light_dir
from models.avatars.mesh import MeshField
from models.avatars.primitives import dispatch, march
from models.avatars.primitives.chart import (
    GAZE_JOINTS,
    GEOMETRY_SCALE_M,
    ChartSampler,
    carried_by,
    chart_sampler,
    expression_share,
    eye_cells,
    face_vertices,
    geometry_map,
    texel_points,
)
from models.avatars.primitives.decoder import SlabDecoder
from models.avatars.primitives.layout import primitive_layout, surface_frames
from models.avatars.primitives.seen import edge_fade, eye_height_m, height_fade, inside_share, voxel_heights
from models.avatars.rendering import RenderOptions
from models.capture.frames import frame_camera
from models.head.controls import Controls
from models.head.lbs import rotation_matrix_from_axis_angle
from models.head.model import HeadModel
from models.ranges import Range, check_config
from render.camera import Camera, project
from render.gl.raster import Rasterizer
from render.gl.shadow import draw_light_depth
from render.rays import Coverage, Rays
from render.shadow_map import LightDepthMap

EXPRESSION_MAP_UNIT_M = 0.01
"""Expression maps are in centimetres: an expression moves the face by millimetres to a few centimetres."""
DISPLAY_PARALLEL_RAYS = 4096
"""Display marches a batch of at least this many rays in as many groups as torch has threads (march_in_parts), on
the CPU (display_groups)."""


def display_groups(rays: int, device: torch.device, cores: int) -> int:
    """How many groups display marches a batch of rays in, each on a thread of its own: `cores` for a large batch on
    the CPU, else one. On a GPU the march is thousands of small kernels whatever the group: groups on threads only
    queue them against each other (a whole head's 128 px frame on an H200: 983 ms in 16 groups, one a thread of the
    machine's 16, against 129 ms in one).

    >>> display_groups(10_000, torch.device("cpu"), 2), display_groups(100, torch.device("cpu"), 2)
    (2, 1)
    >>> display_groups(10_000, torch.device("meta"), 16)  # any device but the CPU
    1
    """
    return cores if rays >= DISPLAY_PARALLEL_RAYS and device.type == "cpu" else 1


@dataclass(frozen=True)
class PrimitivesConfig:
    """Sizes of the primitives and their decoder."""

    grid: Annotated[int, Range(8, 256)] = 16
    """K: primitives on a K x K chart of the head (a power of two; cells the head does not fill have none)."""
    front: Annotated[float, Range(0, 4)] = 0.0
    """How much the chart's columns crowd to the face (layout.chart_azimuths): 0 even (22.5 degrees a column at
    K = 16); 2 gives the face 12.4-degree columns, and so primitives 0.6x as wide, the sides about the same and the
    back of the head 2x, where a monocular video never looks."""
    voxels: Annotated[int, Range(2, 64)] = 8
    """M: each primitive's grid is M^3 voxels (a power of two)."""
    width: Annotated[int, Range(8, 1024)] = 64
    """Channels of the decoder's first feature maps (halved down to 16 as they grow)."""
    code_dim: Annotated[int, Range(0, 1024)] = 8
    """The per-frame code."""
    samples: Annotated[int, Range(1, 256)] = 8
    """Samples each segment of a ray within a primitive takes (the quality presets change it)."""
    density_scale: Annotated[float, Range(0, 1e6, above=True)] = 400.0
    """Densities are softplus(raw - 1) times this, per metre: a raw 0 lets 70% of the light through 1 cm."""
    stop_below: Annotated[float, Range(0, 1)] = 1e-3
    """Display stops a ray once less than this share of its light gets through (early termination)."""
    volume: Annotated[float, Range(0)] = 1e-3
    """The volume prior's weight (the primitives' mean volume over their starting volume)."""
    offsets: Annotated[float, Range(0)] = 1e-3
    """The offsets' L2 weight."""
    codes: Annotated[float, Range(0)] = 1e-3
    correction_prior: Annotated[float, Range(0)] = 1e-4
    """The weight of the per-frame pose and expression corrections' priors (a tracked video's;
    components/poses.py)."""
    code_swap: Annotated[float, Range(0, 1)] = 0.0
    """Share of training steps (on a capture with code keys: a tracked video) whose frame decodes with the code a
    held-out frame of its controls would get (components/codes.py left_out_weights), so that the decoder learns to
    do with the codes new controls get."""
    keep_size: bool = False
    """The primitives grow but never shrink below their places' size (the layout's half-sizes, which overlap their
    neighbours by 1.3): the volume prior pulls none under it. Without it, on the child's video (from scratch, 4131
    steps), every box shrank to about 0.8 of its size, the overlap fell to about 1.04 and, under the opacity window,
    the seams between the boxes emptied: the rays of a camera a few degrees beyond the captured views slipped
    through them onto colours inside the head (dark speckles on the cheeks, on a lattice)."""
    stretch_at_most: Annotated[float, Range(1, 1000)] | None = None
    """Shown, a primitive's longest axis is at most this many times its shortest (None: no limit; each grows up to
    e^3 times its place's size in any case). Training leaves its boxes as the decoder makes them."""
    face_depth: Annotated[float, Range(0)] = 0.0
    """The weight of the face's depth term (0.1 for a tracked video: VIDEO_SETTINGS): on each training ray that meets
    the face of the guide mesh (chart.face_vertices' triangles, less the eyeballs), the share of its light
    composited further than face_margin_m in front of or behind the mesh, so that the face is a surface about the
    tracked mesh and not the video's picture smeared in depth; 0: none (no raster kept for training)."""
    face_margin_m: Annotated[float, Range(0, 1, above=True)] = 0.02
    """The face's depth term leaves the light composited within this of the tracked mesh along the ray alone: the
    tracked surface's own error (a few millimetres), a fringe on the forehead and glasses' rims (about 1.5 cm before
    the eyes' surface) lie within it. At 10 minutes (docs/results.md), 1.5 cm cost the grimacing man's held-out
    frames 0.8 dB (the built-in head cannot make his grimaces, so his face lies off its mesh) and gave d3's furthest
    turns 1.0; 3 cm kept him, lost the turns' gain and the clean face 20 degrees round; 2 cm kept him, a third of the
    turns' gain and the clean face. The band is the tracked pose's: with `--corrections` a frame's corrected rays
    meet the mesh a little elsewhere (the corrections are millimetres; the margin takes them in)."""
    neck_fade: bool = False
    """Shown, the density fades out down the neck by each voxel's height in the head's own frame (seen.py
    NECK_FADE_M below the eyes): the neck ends in a soft edge from every side, not in its lowest boxes' faces. A whole
    head's outside, which shows where the video did not look (whole/avatar.py); training decodes as the decoder makes
    it, and an avatar shown in the video's own views keeps the neck and shoulders the frames showed."""
    opacity_window: bool = False
    """Each primitive's opacity is weighted by MVP's window exp(-8 (x^8 + y^8 + z^8)) over its box (x, y, z in
    [-1, 1]): 1 in its middle, 0.26 at 0.8 of the way out, nothing on its faces, so no box's edge shows from any
    side (neighbours overlap by 1.3 and cover the seams). On for a tracked video (VIDEO_SETTINGS); avatars made
    before it have it off."""
    expression_maps: bool = False
    """The decoder also reads the frame's expression as the guide mesh shows it, in its own layout: each texel's
    surface point (chart.py) with the head's rigid pose taken out, less the neutral face's, in centimetres (the
    seed's Delta G, Cao et al. 2022 Eq. 1), joined at every level from K x K up. A mouth's change then reaches the
    mouth's slabs where it is, where the global condition spreads every expression weight over the whole head."""
    global_expression: bool = True
    """The decoder reads the controls (expression weights, jaw and neck rotations) as one vector that reaches every
    slab. False (with expression_maps): they reach it only as the maps do, where the mesh moves, as the prior's
    decoder has them; a new mix of expressions (eyes of one frame, mouth of another) is then decoded from the
    parts that each training frame showed."""
    gaze_at_eyes: bool = False
    """Gaze (the eyes' rotations) joins the decoder's 8x8 features only over the chart's cells on and beside the
    eyeballs (chart.eye_cells, the prior's masked gaze), not over the whole head."""
    code_off_face: bool = False
    """The per-frame code joins the decoder at the K x K level, weighted on each cell by the share of it that the
    controls do not move (1 - chart.expression_share), instead of reaching every slab: a frame's face is decoded
    from its controls and maps alone, the code keeps what the guide mesh cannot say (hair, shoulders, collar).
    A held-out frame's blended code then cannot bring other frames' eyes and mouths."""
    body_layer: bool = False
    """A picture of what moves with the body (shoulders, collar, clothes) at the neck, behind the head's primitives
    and in front of the plate, in the capture's camera alone (components/body.py); its unseen texels continue the
    nearest seen ones (a frame drawn back shows more of the clothes, not the room)."""
    chunk_rays: Annotated[int, Range(1, 1 << 22)] = 1 << 18
    """Rays a batch when rendering an image: a 512 px frame in one (the waves hold a few tensors of R rays)."""
    reach: Annotated[float, Range(1, 10)] = 2.0
    """Rendered pixels reach this many of the largest primitive half-sizes beyond the mesh's silhouette."""

    def __post_init__(self):
        if not self.global_expression and not self.expression_maps:
            raise ValueError("global_expression false needs expression_maps true: the decoder would read no "
                             "expression at all")
        if self.code_off_face and self.code_dim == 0:
            raise ValueError("code_off_face needs a per-frame code (code_dim > 0)")


VIDEO_SETTINGS = {"front": 2.0, "expression_maps": True, "global_expression": False, "opacity_window": True,
                  "keep_size": True, "body_layer": True, "face_depth": 0.1}
"""PrimitivesConfig's fields for a tracked video (default_config). The opacity window: on d3 held out by view (the
tenth of the frames turned furthest, `track --split view`), the same 1806 steps, 24.60 dB against 24.22 without it
(validation 30.59 against 30.42), and from 45 and 90 degrees beyond the captured views soft edges where the boxes'
square edges showed (docs/results.md). Kept sizes: on the child's video (4131 steps from scratch) 28.29 dB held out
against 28.37, and 20 degrees beyond the views the cheeks' lattice of dark speckles mostly gone; the larger boxes
cost time: a 256 px test frame 113 against 106 ms on the child, 126 against 110 on d3; 27 minutes of training made
9433 steps against 12436 on the child, 8592 against 11588 on d3 (two trainings at a time both ways; other work took a
little of the machine during the first). The body layer: 10 minutes on the two clips whose held-out error lay lowest in
the frame, 22.86 dB held out against 22.09 on `portrait_seaside` (the camera draws back: its clothes continue where
the plate showed the sea), 23.65 against 23.45 on `woman_blue_wall`, validation level (28.01 / 28.11 against 27.64 /
28.08); at 30 minutes 23.31 against 21.81 and 22.61 against 22.46, d3 25.32 against 24.93, `talking_earrings` 25.95
against 25.85; a 256 px frame 97 against 92 ms. The face's depth (face_depth 0.1, 2 cm either side): at 10 minutes
d3 held out by view 24.65 dB against 24.30 (the furthest turns), the grimacing man's held-out frames 32.11 against
31.96, and from 10-20 degrees round a face where the speckles and the hair's strands drawn across it were; a 256 px
frame 10-20% faster (the face's rays close at the surface); docs/results.md "The face's depth"."""


def opacity_window(voxels: int, like: torch.Tensor) -> torch.Tensor:
    """(M,M,M) MVP's opacity window exp(-8 (x^8 + y^8 + z^8)) at a primitive's voxel centres (x, y, z from -1 to 1
    across the box; Lombardi et al., "Mixture of Volumetric Primitives", Sec. 3.3).

    >>> w = opacity_window(5, torch.zeros(())); [round(float(w[2, 2, k]), 4) for k in range(5)]
    [0.0003, 0.9692, 1.0, 0.9692, 0.0003]
    """
    u = torch.linspace(-1.0, 1.0, voxels, dtype=like.dtype, device=like.device).pow(8)
    return torch.exp(-8.0 * (u[:, None, None] + u[None, :, None] + u[None, None, :]))


@dataclass
class PrimitivesGeometry:
    """One frame as the primitives see it: the posed mesh, the head's rigid pose, the decoder's inputs from the
    controls, and the decode of this frame (display: made once, on first use)."""

    posed: torch.Tensor  # (V,3)
    rotation: torch.Tensor  # (3,3) head -> world
    translation: torch.Tensor  # (3,)
    condition: torch.Tensor  # (1,D) expression and jaw/neck rotations
    gaze: torch.Tensor  # (1,6)
    code_weights: torch.Tensor | None = None
    light: LightDepthMap | None = None  # the posed mesh seen from the key light, where the avatar casts shadows
    controls: Controls | None = None  # what posed the mesh (expression corrections pose it again)
    expression: torch.Tensor | None = None  # (1,3,S,S) the expression map (Delta G), where the decoder reads one
    body: tuple[torch.Tensor, torch.Tensor] | None = None  # the body layer's plane (origin, axes), where it has one
    decoded: dict = field(default_factory=dict)

    def to(self, device: torch.device | str) -> PrimitivesGeometry:
        w = None if self.code_weights is None else self.code_weights.to(device)
        return PrimitivesGeometry(self.posed.to(device), self.rotation.to(device), self.translation.to(device),
                                  self.condition.to(device), self.gaze.to(device), w,
                                  None if self.light is None else self.light.to(device), self.controls,
                                  None if self.expression is None else self.expression.to(device),
                                  None if self.body is None else tuple(t.to(device) for t in self.body))


def head_frame(controls: Controls, posed: torch.Tensor, root: torch.Tensor) -> torch.Tensor:
    """(V,3) a posed mesh with the controls' own rigid pose taken out exactly, in the head's frame, where the neck
    has not turned (a turned neck's frame is posed anew: PrimitivesAvatar.head_local): every joint hangs from the
    root, so the root's rotation R about its posed place r (the root joint, which carries the translation t) moves
    every vertex alike, v = R (u - r + t) + r, and u = R^T (v - r) + r - t. A fit of one rigid motion to the whole
    mesh, as the geometry's `rotation` is, would take in part of an opened jaw."""
    R = head_turn(controls).to(posed)
    shift = torch.as_tensor(np.asarray(controls.translation), dtype=posed.dtype, device=posed.device)
    return (posed - root) @ R + (root - shift)


class PrimitivesAvatar(PoseCorrected, Avatar):
    name: ClassVar[str] = "primitives"
    rays_per_step: ClassVar[int] = 2048
    frames_per_step: ClassVar[int] = 2
    """Each frame of a step is decoded apart (its codes and condition), 35 ms forward and backward on one thread of
    this machine's AMD EPYC, so a step of 2 frames takes 0.22 s where 4 took 0.36 (the same 2048 rays): 1.65 times
    the steps in a budget, which on a video gain more than the step's wider view of the frames (docs/results.md
    "Two frames a step")."""
    quality_knobs: ClassVar[tuple[str, ...]] = ("samples",)
    config_class: ClassVar[type] = PrimitivesConfig
    config_key: ClassVar[str] = "primitives"
    """avatar.json's entry for the sizes."""
    optional_buffers: ClassVar[tuple[str, ...]] = (*Avatar.optional_buffers, "seen_fade")
    normals_from_surface: ClassVar[bool] = True
    reads_raster: ClassVar[bool] = False
    """Every pixel's ray, without rasterizing the mesh: the march's screen tiles find the rays that may meet a
    primitive, and a ray on no tile's list costs nothing."""
    """The opacity grids' gradients, voxel by voxel, are noise (41 degrees from the truth on the demo's capture):
    the normals buffer is the rendered surface's (base.py)."""

    def __init__(self, head_model: HeadModel, cfg: PrimitivesConfig, n_frames: int, background: np.ndarray,
                 effects: tuple[str, ...] = (), light_dir: tuple[float, float, float] | None = None):
        super().__init__(head_model, n_frames, background)
        self.cfg = cfg
        self.displayed_by: dispatch.Ran | None = None
        """Which march displayed the last batch (display_march)."""
        self._effects = tuple(effects)
        self.light_dir = light_dir if effects else None
        """The capture's key light (world, towards it) where it records one and the effects call for light: the
        decoder reads its direction in the head's frame (colour under that light as the head turns)."""
        layout = primitive_layout(head_model, cfg.grid, front=cfg.front)  # shared: the buffers are copies
        self.register_buffer("layout_triangles", torch.tensor(layout.triangles, dtype=torch.long))
        self.register_buffer("layout_bary", torch.tensor(layout.bary, dtype=torch.float32))
        self.register_buffer("layout_cells", torch.as_tensor(layout.cells[:, 0] * cfg.grid + layout.cells[:, 1]))
        self.register_buffer("layout_half", torch.tensor(layout.half_size_m, dtype=torch.float32))
        self.register_buffer("triangles", torch.as_tensor(np.asarray(head_model.triangles), dtype=torch.long),
                             persistent=False)
        self.condition_dim = head_model.num_expression + 6
        S = cfg.grid * cfg.voxels
        self.register_buffer("gaze_mask", eye_cells(head_model, S, front=cfg.front) if cfg.gaze_at_eyes else None,
                             persistent=False)
        self.register_buffer("code_mask", 1.0 - expression_share(head_model, S, cfg.grid, cfg.front)
                             if cfg.code_off_face else None, persistent=False)
        self.decoder = self.make_decoder()
        self.latent = nn.Embedding(n_frames, cfg.code_dim)
        nn.init.zeros_(self.latent.weight)
        self.pose_corrections: nn.Parameter | None = None
        """(N,6) per training frame, on a tracked video (components/poses.py); None: the poses as given."""
        self.expression_corrections: nn.Parameter | None = None
        """(N,E) per training frame, on a tracked video; None: the expressions as given."""
        self.chart: ChartSampler | None = None
        """The chart at the slabs' texels, where the decoder reads expression maps (made on first use)."""
        self._neutral: tuple[bytes, torch.Tensor] | None = None
        """The neutral face's texel map and the shape it is of (an avatar is one person: one is kept)."""
        self.plate, self.views = Plate(), CaptureViews()
        """What the capture kept (components/): its background plate, where its camera stood."""
        self.code_keys = CodeKeys(head_model.num_expression)
        """The training frames' control keys: new controls take the nearest frames' codes."""
        self.body = BodyLayer() if cfg.body_layer else None
        """What moves with the body behind the head, in the capture's camera (components/body.py)."""

    def make_decoder(self) -> SlabDecoder:
        """The decoder of the frame's condition (expression and jaw/neck unless only the expression maps carry
        them, code, view, the light's direction where the capture records one) and gaze; with cast shadows, the
        shadow map's channel; with expression maps, their three."""
        extra = 3 if self.light_dir is not None else 0
        controls = self.condition_dim if self.cfg.global_expression else 0
        code, apart = (0, self.cfg.code_dim) if self.cfg.code_off_face else (self.cfg.code_dim, 0)
        return SlabDecoder(controls + code + 3 + extra, 6, self.cfg.grid, self.cfg.voxels, 3,
                           self.cfg.width, map_channels=1 if self.casts_shadows else 0,
                           geometry_channels=3 if self.cfg.expression_maps else 0, code_channels=apart)

    def parameter_groups(self) -> list[dict]:
        """PoseCorrected's groups, the body layer's texture apart at BODY_LR_SCALE (a texel learns only from the
        rays that meet it, a few of a step's)."""
        groups = super().parameter_groups()
        if self.body is None:
            return groups
        texture = self.body.texture
        for group in groups:
            group["params"] = [p for p in group["params"] if p is not texture]
        return [*groups, {"params": [texture], "lr_scale": BODY_LR_SCALE}]

    # ---- making and describing -------------------------------------------------------------------------
    @classmethod
    def for_capture(cls, head_model: HeadModel, n_frames: int, background: np.ndarray, effects: tuple[str, ...],
                    lighting: dict | None, config: PrimitivesConfig | None = None) -> PrimitivesAvatar:
        """`none` decodes colour alone; with effects the decoder reads the key light's direction (where the capture
        records one) and, with shading or specular, the normals buffer comes from the opacity grids' gradients."""
        return cls(head_model, config or cls.config_class(), n_frames, background, effects, key_light_dir(lighting))

    @classmethod
    def default_config(cls, tracked: bool) -> PrimitivesConfig | None:
        """A tracked video's avatar: the chart crowded to the face (front 2), where its one camera looks, and the
        controls reaching the decoder only as the expression maps show them (no global expression vector). On the
        three shared clips (README, Real people; `all`, one run each) held-out PSNR d3 26.62, talking_hdtf 27.02,
        d19 32.71, against 25.60, 27.08 and 31.20 with the global vector beside the maps: a new mix of expressions
        is decoded from the parts training frames showed."""
        return replace(cls.config_class(), **VIDEO_SETTINGS) if tracked else None

    @classmethod
    def from_meta(cls, head_model: HeadModel, meta: dict) -> PrimitivesAvatar:
        cfg = cls.config_class(**meta[cls.config_key])
        check_config(cfg)
        light = meta.get("light_dir")
        light = None if light is None else tuple(float(v) for v in light)
        if light is not None and (len(light) != 3 or not np.isfinite(light).all() or np.linalg.norm(light) < 1e-6):
            raise ValueError(f"light_dir {meta['light_dir']}: not a direction (three finite numbers, not all 0)")
        avatar = cls(head_model, cfg, int(meta["frames"]), np.asarray(meta["background"], np.float32),
                     tuple(meta.get("effects", ())), light)
        avatar.restore_corrections(meta)
        return avatar

    def meta(self) -> dict:
        return {"model": self.name, "effects": list(self._effects), self.config_key: asdict(self.cfg),
                "light_dir": None if self.light_dir is None else list(self.light_dir), **self.corrections_meta()}

    def fit_to_tracked_video(self, corrections: bool | None = None) -> None:
        """corrections (default off): learn a correction of each training frame's head pose and expression weights
        with the avatar (components/poses.py; the primitives sit on the mesh the corrected weights pose). Off by
        default: on d3 (`all`, 30 minutes, one run each) the held-out frames, which take none, came out at 25.40 dB
        with pose corrections and 25.55 with pose and expression corrections, against 25.71 without; d19 at 31.72
        with pose corrections against 31.51."""
        if corrections:
            self.correct_poses()
            self.correct_expressions(self.head_model.num_expression)

    def pose_centre(self, geometry: PrimitivesGeometry) -> torch.Tensor:
        """The middle of the posed mesh's box."""
        return 0.5 * (geometry.posed.min(0).values + geometry.posed.max(0).values)

    @property
    def needs_normals(self) -> bool:
        return "shading" in self._effects or "specular" in self._effects

    @property
    def casts_shadows(self) -> bool:
        """The decoder reads the key light's visibility of every primitive's texels (the guide mesh's shadow map):
        `shadows` on a capture that records its key light."""
        return "shadows" in self._effects and self.light_dir is not None

    def shown_channels(self, lit: bool = False, options: RenderOptions | None = None) -> tuple[str, ...]:
        """The colour grids' channels beyond rgb that display composites: the key light's visibility (1, for
        rgb_light) where the avatar casts shadows and the render makes the buffer (options.buffers); none for the
        lit inspection pass (its rgb alone). The normals are the surface's (normals_from_surface), not composited."""
        want = None if options is None else options.buffers
        return ("rgb_light",) if self.casts_shadows and not lit and (want is None or "rgb_light" in want) else ()

    def layout(self) -> dict[str, tuple[int, float | str]]:
        return super().layout() | {"normals": (3, 0.0), "rgb_light": (3, 1.0), "rgb_no_shadows": (3, BACKGROUND)}

    @classmethod
    def buffer_names(cls, meta: dict) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The normals with shading or specular; where the avatar casts shadows, rgb_light: the key light's
        visibility (1: no cast shadow), grey, composited as the colour is, and rgb_no_shadows: the render decoded
        with every texel lit (the shadow map's input at 1)."""
        effects = meta.get("effects", ())
        normals = ("normals",) if "shading" in effects or "specular" in effects else ()
        shadows = "shadows" in effects and meta.get("light_dir") is not None  # casts_shadows
        return normals, ("rgb_no_shadows", "rgb_light") if shadows else ()

    def inspect(self, out: RayOutput, geometry: PrimitivesGeometry, names: tuple[str, ...]) -> dict[str, torch.Tensor]:
        unknown = set(names) - set(self.inspection_buffers())
        if unknown:
            raise ValueError(f"{self.name} avatars with effects {self.describe_effects()} have no buffers {unknown}")
        _, _, marched, rays, frame, options = out.internals
        found = {}
        if "rgb_light" in names:
            light, opacity = marched.extra[:, -1:], out.buffers["opacity"][:, None]
            found["rgb_light"] = (light + (1.0 - opacity)).clamp(0, 1).expand(-1, 3)  # lit where nothing is
        if "rgb_no_shadows" in names:
            lit = self.render_rays(rays, geometry, frame, options=options, lit=True)
            found["rgb_no_shadows"] = lit.buffers["rgb"]
        return found

    @property
    def effects(self) -> tuple[str, ...]:
        return self._effects

    @property
    def count(self) -> int:
        return len(self.layout_triangles)

    def describe_rendering(self) -> str:
        c = self.cfg
        return f"{self.count} primitives of {c.voxels}^3 voxels, {c.samples} samples a segment"

    @property
    def chunk_rays(self) -> int:
        return self.cfg.chunk_rays

    @property
    def interactive_chunk_rays(self) -> int:
        """A 256 px frame in one batch in the window: the march's per-batch work (tile lists, packed grids, waves)
        does not repeat, and its groups run on the renderer's cores; a new slider value waits for at most the
        frame in flight. Measured on the demo at 256 px (`final`, the studio's 3/4 view, alone): 298 / 224 / 219
        ms a frame in batches of 4096 / 16384 / 65536 rays on one thread, 435 / 199 / 154 ms in two groups on
        two threads."""
        return 1 << 16

    # ---- per frame -------------------------------------------------------------------------------------
    @torch.no_grad()
    def geometry(self, controls: Controls, time_s: float | None = None) -> PrimitivesGeometry:
        unposed = Controls(shape=controls.shape, expression=controls.expression)
        v, joints, _ = self.head.pose([unposed, controls])
        rotation, translation = head_pose(self.head_model, controls, v, joints)
        E = self.head_model.num_expression
        cond = np.zeros(self.condition_dim, np.float32)
        n = min(len(controls.expression), E)
        cond[:n] = controls.expression[:n]
        cond[E:E + 3], cond[E + 3:E + 6] = controls.rotation("jaw"), controls.rotation("neck")
        gaze = np.concatenate([controls.rotation(j) for j in GAZE_JOINTS]).astype(np.float32)
        held = self.code_keys.trained_range(GAZE_KEYS)
        if held is not None:  # the decoder reads the gaze everywhere (the eyes turn with their joints regardless):
            gaze = np.clip(gaze, *held).astype(np.float32)  # beyond what training showed, the eyes came out smeared
        as_t = lambda a: torch.as_tensor(a)[None].to(v.device)
        body = None if self.body is None else body_frame(
            joints[1], rotation_matrix_from_axis_angle(torch.as_tensor(controls.root, dtype=v.dtype)),
            self.head_model.joint_names)
        return PrimitivesGeometry(v[1], rotation, translation, as_t(cond), as_t(gaze),
                                  self.code_keys.weights(controls, time_s), controls=controls,
                                  expression=self.controls_expression_map(controls, v[1], joints[1, 0]), body=body)

    def frame_geometry(self, controls: Controls, rasterizer: Rasterizer | None, time_s: float | None = None
                       ) -> PrimitivesGeometry:
        """The frame's geometry; where the avatar casts shadows, with the posed mesh's depth map from the key light
        (drawn by the GL rasterizer). Rays need no raster: the primitives' own boxes say which rays meet them."""
        geo = self.geometry(controls, time_s)
        if not self.casts_shadows:
            return geo
        if rasterizer is None:
            raise ValueError("this avatar's decoder reads the posed mesh's shadow map: pass a rasterizer")
        light = draw_light_depth(rasterizer, geo.posed.cpu().numpy(), self.head_model.triangles, self.light_dir)
        geo.light = light.to(geo.posed.device)
        return geo

    def mesh_field(self, controls: Controls, rasterizer: Rasterizer | None) -> MeshField:
        from models.avatars.primitives.mesh import primitives_mesh_field

        return primitives_mesh_field(self, controls)

    @torch.no_grad()
    def slab_visibility(self, geo: PrimitivesGeometry, centres: torch.Tensor, rotations: torch.Tensor
                        ) -> torch.Tensor:
        """(1,1,K M,K M) the key light's visibility (render/shadow_map.py, 1: lit) of each primitive's M x M
        texels on its surface plane (z = 0 of its box, where it sits on the mesh), in the slab's layout: rows
        (grid row, y), columns (grid column, x); 1 in cells without a primitive."""
        K, M = self.cfg.grid, self.cfg.voxels
        s = torch.linspace(-1.0, 1.0, M, device=centres.device) if M > 1 else torch.zeros(1, device=centres.device)
        y, x = torch.meshgrid(s, s, indexing="ij")
        local = torch.stack([x, y, torch.zeros_like(x)], -1).reshape(1, M * M, 3) * self.layout_half[:, None, None]
        points = centres[:, None] + torch.einsum("pij,pkj->pki", rotations, local)
        vis = geo.light.visibility(points.reshape(-1, 3)).reshape(-1, M, M)
        image = torch.ones(K * K, M, M, device=vis.device)
        image[self.layout_cells] = vis
        return image.reshape(K, K, M, M).permute(0, 2, 1, 3).reshape(1, 1, K * M, K * M)

    def image_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        return np.ones((camera.height_px, camera.width_px), bool)

    @property
    def shows_body(self) -> bool:
        """Whether the body layer shows in the capture's frames: the avatar has one and the capture a plate (a
        tracked video's room) for the frames' rays to carry; a capture with a background colour never shows it."""
        return self.body is not None and self.plate.camera is not None

    def training_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        """The mesh's pixels and those within `reach` of its largest primitive's half-size beyond them."""
        if not raster.hit.any():
            return np.zeros_like(raster.hit)
        near = float(raster.depth[np.isfinite(raster.depth)].min())
        margin = self.cfg.reach * float(self.layout_half.max()) * camera.focal_px() / max(near, 1e-3)
        pixels = binary_dilation(raster.hit, iterations=max(1, int(np.ceil(margin))))
        if self.shows_body:  # and every pixel below the mesh's lowest, where the body layer shows the clothes
            lowest = int(np.nonzero(raster.hit.any(1))[0].max())
            pixels[max(lowest - int(np.ceil(margin)), 0):] = True
        return pixels

    def codes(self, frame: int | None, weights: torch.Tensor | None = None) -> torch.Tensor:
        """The per-frame code (1,C) of a training frame; new controls: the blend `weights` give, else the mean."""
        return frame_code(self.latent, frame, weights)

    # ---- the decode --------------------------------------------------------------------------------------
    def texel_map(self, vertices: torch.Tensor) -> torch.Tensor:
        """(1,3,S,S) the chart's texels (chart.py, made on first use) on a mesh (V,3) given in the head's frame, in
        centimetres about the template's centre; 0 off the head."""
        if self.chart is None:
            self.chart = chart_sampler(self.head_model, self.cfg.grid * self.cfg.voxels, self.cfg.front)
        return geometry_map(self.chart, self.triangles, vertices)[None] * (GEOMETRY_SCALE_M / EXPRESSION_MAP_UNIT_M)

    def head_local(self, controls: Controls, posed: torch.Tensor, root: torch.Tensor) -> torch.Tensor:
        """(V,3) the frame's posed mesh with its own rigid pose taken out exactly, in the head's frame: head_frame
        where the neck is still; where the head turned on the body (a tracked video: models/tracking/torso.py), the
        frame posed anew without root, neck and translation (the shoulders stayed: no one rigid motion undoes it)."""
        if not turned_on_body(self.head_model, controls):
            return head_frame(controls, posed, root)
        still = np.zeros(3, np.float32)
        return self.head.pose(replace(controls, root=still, neck=still, translation=still))[0][0]

    @torch.no_grad()
    def controls_expression_map(self, controls: Controls, posed: torch.Tensor, root: torch.Tensor
                                ) -> torch.Tensor | None:
        """Delta G, the frame's expression map (`expression_maps`; None where the decoder reads none): the texels on
        its posed mesh (V,3) in the head's frame (head_local; root: the posed root joint), less those on the
        person's neutral face."""
        if not self.decoder.geometry_channels:
            return None
        local = self.head_local(controls, posed, root)
        key = np.asarray(controls.shape, np.float32).tobytes()
        if self._neutral is None or self._neutral[0] != key:  # the face expressions are measured from
            neutral, _, _ = self.head.pose([Controls(shape=controls.shape)])
            self._neutral = key, self.texel_map(neutral[0])
        if self._neutral[1].device != local.device:  # made on the CPU with a trainer's frames, then the avatar
            self._neutral = key, self._neutral[1].to(local.device)  # went to a GPU (validation, the codes' choice)
        return self.texel_map(local) - self._neutral[1]

    def frame_expression_map(self, geo: PrimitivesGeometry, posed: torch.Tensor) -> torch.Tensor:
        """The frame's expression map, where an expression correction posed its mesh (V,3) again: the change
        turned into the head's frame, R^T (posed - geo.posed), added (a texel is a fixed blend of vertices)."""
        if posed is geo.posed:
            return geo.expression
        centre = torch.as_tensor(self.chart.centre, dtype=posed.dtype, device=posed.device)
        return geo.expression + self.texel_map((posed - geo.posed) @ head_turn(geo.controls).to(posed) + centre)

    def decode_slabs(self, geo: PrimitivesGeometry, condition: torch.Tensor, light: torch.Tensor | None,
                     training: bool, posed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The decoder's raw opacity, colour and offsets for every cell of the grid (SlabDecoder.forward); posed
        (V,3): the mesh the frame decodes on (its expression maps')."""
        del training  # the decoder is deterministic
        geometry = self.frame_expression_map(geo, posed) if self.decoder.geometry_channels else None
        D, C = self.condition_dim, self.cfg.code_dim
        controls, code, rest = condition[:, :D], condition[:, D:D + C], condition[:, D + C:]
        kept = [controls] if self.cfg.global_expression else []  # else the controls reach it as the maps show them
        kept += [rest] if self.cfg.code_off_face else [code, rest]
        return self.decoder(torch.cat(kept, -1), geo.gaze, light, geometry=geometry, gaze_mask=self.gaze_mask,
                            code=code if self.cfg.code_off_face else None, code_mask=self.code_mask)

    @staticmethod
    def view_of(geo: PrimitivesGeometry, eye: torch.Tensor) -> torch.Tensor:
        """(3,) the unit direction from the head to a camera at `eye`, in the head's frame: R^T (eye - t)."""
        view = (eye - geo.translation) @ geo.rotation
        return view / view.norm().clamp_min(1e-9)

    def note_views(self, frames) -> None:
        """Where the capture's camera stood if it stood still, the cone of the views the decoder read (one a frame:
        the direction to each training frame's camera), and how far inside the training frames each texel of the
        chart came (seen.py): the primitives' opacity fades out where the capture stopped seeing the head
        (seen_fade)."""
        pairs = zip(frames.geometry, frames.origins, strict=True)
        views = torch.stack([self.view_of(geo, eye.to(geo.translation)) for geo, eye in pairs])
        self.views.note(frames.origins, views, self.background.device)
        self.note_reach(frames)
        self.note_body(frames)

    @torch.no_grad()
    def note_body(self, frames) -> None:
        """The body layer's texels whose centres some training frame shows on a pixel training draws rays from (the
        FrameSet's `active_index`); the rest show their nearest (BodyLayer.note_seen).
        A texel no training ray reaches (the room far from the person) so shows the nearest one the loss taught, not
        its own untaught start (a haze of START_OPACITY_LOGIT over the room). By centres, not by any pixel falling on
        a texel: a texel a frame's edge cuts a tenth into is taught little, and counted as seen it stood near its
        start and the clothes' fill below it showed clear (`portrait_seaside`'s held-out frames, the avatar noted
        again: 22.88 dB by any pixel, 23.36 by centres; docs/results.md)."""
        if not self.shows_body or getattr(frames, "split", None) is None:
            return
        T = self.body.texels
        seen = np.zeros(T * T, bool)
        for frame, geo, active in zip(frames.split.frames, frames.geometry, frames.active_index, strict=True):
            if geo.body is None:
                continue
            camera = frame_camera(frames.split, frame)
            H, W = camera.height_px, camera.width_px
            trained = np.zeros(H * W, bool)
            trained[active.numpy()] = True
            x, y, depth = project(camera, self.body.texel_centres(geo.body).double().cpu().numpy())
            col, row = np.floor(x), np.floor(y)
            inside = (depth > 0) & (col >= 0) & (col < W) & (row >= 0) & (row < H)
            at = row[inside].astype(np.int64) * W + col[inside].astype(np.int64)
            seen[np.flatnonzero(inside)[trained[at]]] = True
        self.body.note_seen(seen.reshape(T, T))

    @torch.no_grad()
    def note_reach(self, frames) -> None:
        """seen_fade (S,S), in the chart's (and the slabs') layout: 1 on every texel that lay inside some training
        frame (and off the head, where the chart has no texel), falling to 0 EDGE_SHARE of the frame beyond."""
        if getattr(frames, "split", None) is None:  # views without their cameras' images: nothing to measure
            return
        S = self.cfg.grid * self.cfg.voxels
        if self.chart is None:
            self.chart = chart_sampler(self.head_model, S, self.cfg.front)
        reach = np.full(S * S, -np.inf)
        for frame, geo in zip(frames.split.frames, frames.geometry, strict=True):
            points = texel_points(self.chart, self.triangles.to(geo.posed.device), geo.posed).double().cpu().numpy()
            reach = np.maximum(reach, inside_share(points, frame_camera(frames.split, frame)))
        reach = torch.as_tensor(np.where(self.chart.valid, reach, np.inf), dtype=torch.float32)
        self.register_buffer("seen_fade", edge_fade(reach).reshape(S, S).to(self.background.device))

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        """An avatar trained before seen_fade came fades nothing, resumed too: `train --resume` notes the views, and
        so makes the buffer, before it loads weights that have none."""
        if prefix + "seen_fade" not in state_dict and "seen_fade" in self._buffers:
            del self._buffers["seen_fade"]
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def slab_fade(self) -> torch.Tensor | None:
        """(P,1,M,M) seen_fade at each primitive's voxel columns (the slab's layout, as slab_visibility's), or None
        where the avatar has none."""
        fade = getattr(self, "seen_fade", None)
        if fade is None:
            return None
        K, M = self.cfg.grid, self.cfg.voxels
        return fade.reshape(K, M, K, M).permute(0, 2, 1, 3).reshape(K * K, 1, M, M)[self.layout_cells]

    def frame_inputs(self, geo: PrimitivesGeometry, frame: int | None) -> tuple[torch.Tensor, torch.Tensor]:
        """The posed mesh (V,3) and the condition (1,D) the decode reads: a training frame's with its expression
        correction (the mesh posed again with the corrected weights), else the geometry's own."""
        if self.expression_corrections is None or frame is None or geo.controls is None:
            return geo.posed, geo.condition
        delta = self.expression_correction(frame)
        batch = self.head.batch([geo.controls])
        batch["expression"] = batch["expression"] + delta.to(batch["expression"])
        E = len(delta)
        condition = torch.cat([geo.condition[:, :E] + delta, geo.condition[:, E:]], -1)
        return self.head(**batch)[0][0].to(geo.posed), condition

    def decode(self, geo: PrimitivesGeometry, code: torch.Tensor, eye: torch.Tensor, lit: bool = False,
               training: bool = False, frame: int | None = None, extras: tuple[str, ...] | None = None
               ) -> tuple[march.Primitives, torch.Tensor]:
        """The frame's primitives, placed on its posed mesh, and their offsets, for a camera at `eye` (3,) (the view
        enters the decoder as the direction to the eye in the head's frame, held to the capture's cone: base.py).
        lit: every texel lit (no cast shadows). training: colour alone (the buffers' extra channels are display's).
        frame: a training frame's expression correction (frame_inputs)."""
        posed, condition = self.frame_inputs(geo, frame)
        view = self.views.seen(self.view_of(geo, eye)[None])[0]
        inputs = [condition, code, view[None]]
        if self.light_dir is not None:
            inputs.append((torch.as_tensor(self.light_dir, dtype=view.dtype, device=view.device) @ geo.rotation)[None])
        centres, rotations = surface_frames(posed, self.triangles, self.layout_triangles, self.layout_bary)
        light = None if not self.casts_shadows else torch.ones(1, 1, self.cfg.grid * self.cfg.voxels,
                                                                 self.cfg.grid * self.cfg.voxels, device=code.device) \
            if lit else self.slab_visibility(geo, centres, rotations)
        density_raw, colour_raw, offsets = self.decode_slabs(geo, torch.cat(inputs, -1), light, training, posed)
        cells = self.layout_cells
        density_raw, colour_raw, offsets = density_raw[cells], colour_raw[cells], offsets[cells]
        scale = offsets[:, 6:9].clamp(0.0 if self.cfg.keep_size else -3.0, 3.0)
        if self.cfg.stretch_at_most is not None and not training:
            scale = torch.minimum(scale, scale.min(1, keepdim=True).values + math.log(self.cfg.stretch_at_most))
        half = self.layout_half[:, None] * torch.exp(scale)
        centres = centres + (rotations @ (offsets[:, :3] * self.layout_half[:, None])[..., None])[..., 0]
        rotations = rotations @ rotation_matrix_from_axis_angle(offsets[:, 3:6])
        density = F.softplus(density_raw - 1.0) * self.cfg.density_scale
        if self.cfg.opacity_window:
            density = density * opacity_window(self.cfg.voxels, density)
        fade = self.slab_fade()
        if fade is not None:  # nothing where the capture never looked (seen.py)
            density = density * fade.to(density)
        eyes = self.eye_height if self.cfg.neck_fade and not training else None
        if eyes is not None:  # a soft end to the neck (seen.py)
            density = density * height_fade(voxel_heights(centres, rotations, half, self.cfg.voxels, geo.rotation,
                                                          geo.translation), eyes).to(density)
        colour = torch.sigmoid(colour_raw)
        extras = self.shown_channels(lit) if extras is None else extras
        if training:  # no loss reads the normals or the visibility: the march composites colour alone
            return march.Primitives(centres, rotations, half, density, colour), offsets
        if "rgb_light" in extras:  # each texel's visibility through its column of voxels: the rgb_light buffer
            K, M = self.cfg.grid, self.cfg.voxels
            texels = light.reshape(K, M, K, M).permute(0, 2, 1, 3).reshape(K * K, 1, M, M, 1)[cells]
            colour = torch.cat([colour, texels.expand(-1, M, -1, -1, -1)], -1)
        return march.Primitives(centres, rotations, half, density, colour), offsets

    @cached_property
    def eye_height(self) -> float | None:
        """seen.eye_height_m of the head model, worked out once (the neck fade reads it at every decode)."""
        return eye_height_m(self.head_model)

    @cached_property
    def face_triangles(self) -> np.ndarray:
        """(F,) the triangles of the face's surface (face_vertices' but the eyeballs', which the lids cover)."""
        on_face = face_vertices(self.head_model) & ~carried_by(self.head_model, GAZE_JOINTS)
        return on_face[np.asarray(self.head_model.triangles)].all(1)

    def training_code(self, frame: int, generator: torch.Generator | None) -> torch.Tensor:
        """(1,C) the code a training step decodes with: the frame's own, or on code_swap's share of the steps the
        code of the frame left out (left_out_weights)."""
        keys = self.code_keys.keys
        if keys is None or self.cfg.code_swap <= 0 or generator is None \
                or float(torch.rand((), generator=generator)) >= self.cfg.code_swap:
            return self.codes(frame)
        return left_out_weights(keys, frame)[None] @ self.latent.weight

    def decoded(self, geo: PrimitivesGeometry, frame: int | None, eye: torch.Tensor, training: bool,
                lit: bool = False, code: torch.Tensor | None = None, options: RenderOptions | None = None):
        """decode, cached on the geometry for display (one decode a frame, and one lit for inspection, whatever
        the batches of rays), with the channels the render shows (shown_channels of `options`). code: instead of
        the frame's (training_code)."""
        code = self.codes(frame, geo.code_weights) if code is None else code
        if training:
            return self.decode(geo, code, eye, lit, training=True, frame=frame)
        key = (frame, tuple(round(float(x), 6) for x in eye.detach()))
        if geo.decoded.get("key") != key:
            geo.decoded.clear()
            geo.decoded["key"] = key
        extras = self.shown_channels(lit, options)
        if (lit, extras) not in geo.decoded:
            geo.decoded[lit, extras] = self.decode(geo, code, eye, lit, frame=frame, extras=extras)
        return geo.decoded[lit, extras]

    # ---- rays ------------------------------------------------------------------------------------------
    @property
    def trains_on_surface(self) -> bool:
        return self.cfg.face_depth > 0

    def training_surface(self, raster) -> np.ndarray:
        """The distance to the guide mesh on the pixels where it shows the face (face_vertices' triangles) but not
        an eyeball, inf elsewhere: the crown and the back of the mesh lie under the hair, not on it, and the lids
        cover the head model's eyeballs as the video's eyes open and close (held to them, a white blob showed on an
        eye from 15 degrees round)."""
        on = (raster.triangle >= 0) & self.face_triangles[np.maximum(raster.triangle, 0)]
        return np.where(on, raster.distance, np.inf)

    def face_band(self, rays: Rays) -> tuple[torch.Tensor, torch.Tensor]:
        """(lo, hi) (R,) along each ray, face_margin_m either side of the mesh's face where the ray meets it
        (Rays.surface_t), everything where it does not."""
        t, m = rays.surface_t, self.cfg.face_margin_m
        on = torch.isfinite(t)
        inf = torch.full_like(t, float("inf"))
        return torch.where(on, t - m, -inf), torch.where(on, t + m, inf)

    def render_rays(self, rays: Rays, geometry: PrimitivesGeometry, frame: int | None,
                    generator: torch.Generator | None = None, training: bool = False,
                    options: RenderOptions | None = None, lit: bool = False,
                    band: tuple[torch.Tensor, torch.Tensor] | None = None) -> RayOutput:
        """rgb, opacity and depth of R rays marched through the primitives they meet (one pinhole's rays are
        binned in screen tiles, march.candidate_lists). lit: decoded with every texel lit (inspection). band
        (training): march's, the march output's off_band then each ray's light outside it."""
        if self.pose_corrections is not None and frame is not None:
            rays = self.corrected_rays(rays, geometry, frame)
        code = self.training_code(frame, generator) if training and frame is not None else None
        prims, offsets = self.decoded(geometry, frame, rays.origins.mean(0), training, lit, code, options)
        behind = self.behind(rays, geometry)
        if training:
            out, _ = dispatch.march_rays(rays.origins, rays.directions, behind, prims, self.cfg.samples, band=band)
        else:
            out = self.display_march(rays.origins, rays.directions, behind, prims, options)
        buffers = {"rgb": out.rgb, "opacity": out.opacity, "depth": out.depth}
        return RayOutput(buffers, (prims, offsets, out, rays, frame, options))

    def behind(self, rays: Rays, geometry: PrimitivesGeometry) -> torch.Tensor:
        """What each ray sees behind the primitives: the plate's pixel (or the colour), with the body layer over the
        plate where the avatar has one and the rays carry the plate (the capture's camera: components/body.py)."""
        background = self.ray_background(rays)
        if self.body is None or rays.background is None or geometry.body is None:
            return background
        return self.body.over(background, rays.origins, rays.directions, geometry.body)

    def display_march(self, origins: torch.Tensor, directions: torch.Tensor, background: torch.Tensor,
                      prims: march.Primitives, options: RenderOptions | None = None) -> march.MarchOutput:
        """The march as display runs it (and the bench times it): in C where it can, else in torch (dispatch.py; what
        ran is kept for describe_display); the rays in as many groups as options.cores (else torch's threads; one
        thread a group); in waves with early termination, samples by the voxels a segment crosses, colour looked up
        only where it shows; options.should_stop asked between waves."""
        options = options or RenderOptions()
        cores = options.cores or torch.get_num_threads()
        parts = display_groups(len(origins), origins.device, cores)
        display = dispatch.Display(self.cfg.stop_below, parts, options.should_stop)
        samples = self.cfg.samples if options.quality is None else options.quality.samples
        out, self.displayed_by = dispatch.march_rays(origins, directions, background, prims, samples, display)
        return out

    def describe_display(self) -> str:
        """The march of the last display batch: "C", or torch and why (dispatch.Ran); "" before any."""
        return "" if self.displayed_by is None else str(self.displayed_by)

    def loss_terms(self, batch: TrainingBatch) -> dict[str, torch.Tensor]:
        band = self.face_band(batch.rays) if self.cfg.face_depth > 0 else None
        out = self.render_rays(batch.rays, batch.geometry, batch.frame, batch.generator, training=True, band=band)
        terms = {"photometric": losses.photometric(out.buffers["rgb"], batch.target), **self.regularisers(out),
                 "codes": self.cfg.codes * losses.code_l2(self.codes(batch.frame))}
        if band is not None:  # the face's light composited off the tracked surface (its share, over every ray)
            terms["face_depth"] = self.cfg.face_depth * out.internals[2].off_band.mean()
        if self.pose_corrections is not None:
            terms["pose_corrections"] = self.cfg.correction_prior * self.pose_correction_term(batch.frame)
        if self.expression_corrections is not None:
            terms["expression_corrections"] = self.cfg.correction_prior * self.expression_correction_term(batch.frame)
        return terms

    def regularisers(self, out: RayOutput) -> dict[str, torch.Tensor]:
        """MVP's volume prior (the primitives' mean volume over their starting volume) and the offsets' L2."""
        prims, offsets = out.internals[:2]
        volume = (prims.half_sizes.prod(1) / self.layout_half.pow(3)).mean()
        return {"volume": self.cfg.volume * volume, "offsets": self.cfg.offsets * offsets.square().sum(1).mean()}
