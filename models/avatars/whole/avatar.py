"""A whole head from a video that saw one side of it: the avatar trained on the video (primitives from scratch,
`inside`) where the video saw the head, and the universal prior personalised on the same video (`outside`) where
it did not, blended ray by ray. `train --model whole` makes one (models/training/whole.py); `train` does for a
tracked video.

Why two: on real clips held out by view, the avatar trained from scratch is the sharper one where the video
looked (31.7 and 35.3 dB against 28.6 and 31.1 for 3 minutes of personalising the prior), and the prior is the
only one with a head where it did not (a turntable of the scratch avatar breaks into blocks and holes from about
60 degrees; docs/results.md). Personalising the prior for longer sharpens it in view but loses the whole head.

Which of the two a ray shows: every ray the inside where the ray's camera stands within the cone of the capture's
views (the inside's CaptureViews, the directions its decoder read: its own views are rendered exactly as the inside
alone renders them). Beyond the cone, by where the ray meets the head (taken as a sphere about its centre): the
inside where that point faces a direction within the cone, widened by a margin that shrinks as the camera leaves the
cone (SWEEP_DEG at its rim, 0 from VIEW_FADE_DEG's end), the outside where it faces further round, and both rendered
and their buffers mixed by a smoothstep over FACING_FADE_DEG between. So as the camera turns away from what the
video saw, the boundary sweeps across the head from its far side to the cone's rim, and only the rays near it
render twice: a frame costs little more than one part does. And the inside's share of every ray falls with the
camera's own angle beyond the cone (SEEN_FADE_DEG): from 15 degrees beyond, every ray the inside shows renders both,
and from 30 the frame is the outside's alone."""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
import torch
import torch.nn.functional as F

from models.avatars.base import Avatar, RayOutput, TrainingBatch
from models.avatars.mesh import MeshField
from models.avatars.primitives.avatar import PrimitivesAvatar, PrimitivesGeometry
from models.avatars.prior.avatar import PriorAvatar
from models.head.controls import Controls
from models.head.model import HeadModel
from render.camera import Camera
from render.gl.raster import Rasterizer
from render.rays import Coverage, Rays

VIEW_FADE_DEG = (0.0, 20.0)
"""Over this angle of the camera beyond the captured cone (seen from the head, as the inside's decoder reads its view)
the inside's margin shrinks from SWEEP_DEG to none (smoothstep)."""
SWEEP_DEG = 120.0
"""The inside's margin beyond the cone, in the facing direction, for a camera at the cone's rim: every surface such a
camera sees faces at most about 90 degrees beyond the cone, so the frame is still all inside. Until 27 November
2026 the camera's angle set one weight for the whole frame (both parts rendered every ray of a camera 0-20 degrees
beyond): on the synthetic person seen from the front the frames 25-75 degrees round score 23.24 dB on average
against 23.32 (sweeps from 90 and 180 degrees: 23.22 and 23.18), and the child's whole head renders a live pose in
85 ms against 133 (`benchmarks/bench_live.py`)."""
FACING_FADE_DEG = (0.0, 20.0)
"""A ray meeting the head where it faces this far beyond the captured cone and the margin: all inside, to all outside
(the cone is the views' own, so its rim already saw those surfaces at a slant). 0-40 with the margin: 0.3 dB lower on
the synthetic person 25-75 degrees round. Measured against (10, 40): on the synthetic
person seen from the front 23.62 / 21.17 / 24.01 dB at 45 / 90 / 135 degrees against 23.08 / 20.73 / 23.78, d3's
held-out turns 25.23 against 25.21, and by eye fewer of the inside's speckles on the cheeks at 30-60 degrees."""
SEEN_FADE_DEG = (15.0, 30.0)
"""Over this angle of the camera beyond the captured cone the inside's share of every ray falls from all to none
(smoothstep, times the facing's): the inside's volume draws a clean surface only from about the views it trained
from, and from further round its front is the video's picture smeared through the volume. By the facing alone the
face's front stayed the inside's from every camera, mixed with the outside's head where the cheeks turn away, and
the two faces (the outside's features sit a little elsewhere) showed doubled eyes and noses 30 to 60 degrees round
on real people's whole heads (the README's turntables). Measured: docs/results.md, "Beyond the captured views"."""
EPS = 1e-3
"""Weights within this of 0 or 1 render one model only."""
_AHEAD = ThreadPoolExecutor(1, thread_name_prefix="whole-outside")
"""The outside's decode beside the inside's (WholeHeadAvatar.outside_ahead)."""
OUTSIDE_STOP_BELOW = 1e-2
"""The outside's rays take no more primitives once less than this share of their light gets through (its own
stop_below where that is higher). The prior's primitives are larger and fainter than the inside's, so its rays cross
more of them before they are opaque. On the child's whole head (`python -m benchmarks.bench_whole AVATAR
--outside-settings`; at rest from 20, 90 and 160 degrees, 8 samples): 69 ms a frame against 78 at its own 1e-3, and
51.5 dB from 16 samples marched to 1e-4 against 51.6 (3e-2: 67 ms, 50.6 dB)."""

OUTSIDE_STRETCH = 3.0
"""The outside's primitives are shown with their longest axis within this many times their shortest (its training
leaves them be). Personalised on a video, the boxes about the grimacing man's neck stretched up to 9 times along one
axis and shrank along another (the longest 13.7 times the shortest for 1% of the boxes) to draw, from the front,
the shoulders the video showed; beyond the video's views, where a whole head shows its outside, they were long dark
slabs behind his head from 30 degrees round. The synthetic person's long hair grows its boxes up to 3.2 times,
evenly (the longest axis at most 2.2 times the shortest for 99% of them): this limit leaves its figures as they
were at every angle. Not for the personalised prior on its own (`--model prior`): there the outside is the avatar
in the video's views too, and the limit took the grimacing man's shoulders from his held-out frames (21.88 dB
against 31.45). Tried and not kept: the limit in training too (the decoder made the neck's boxes larger all round:
dark blocks in place of the slabs), and a cap of twice the places' size on every axis (it cut the long hair short:
0.5-2 dB lower from 90 degrees round); docs/results.md, "Beyond the captured views"."""


def smooth_fall(x: torch.Tensor, lo: float, hi: float) -> torch.Tensor:
    """1 up to lo, 0 from hi, smoothstep between (lo < hi).

    >>> smooth_fall(torch.tensor([0.0, 1.0, 1.5, 2.0, 3.0]), 1.0, 2.0).tolist()
    [1.0, 1.0, 0.5, 0.0, 0.0]
    """
    s = ((x - lo) / (hi - lo)).clamp(0.0, 1.0)
    return 1.0 - s * s * (3.0 - 2.0 * s)


def beyond_cone_deg(v: torch.Tensor, axis: torch.Tensor, cos_half: float) -> torch.Tensor:
    """(N,) degrees by which unit directions (N,3) lie outside the cone (axis, cosine of its half-angle); 0 inside.

    >>> v = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    >>> beyond_cone_deg(v, torch.tensor([0.0, 0.0, 1.0]), math.cos(math.radians(30))).round().tolist()
    [0.0, 60.0, 150.0]
    """
    angle = torch.rad2deg(torch.acos((v @ axis.to(v)).clamp(-1.0, 1.0)))
    return (angle - math.degrees(math.acos(min(max(cos_half, -1.0), 1.0)))).clamp_min(0.0)


def sphere_points(origins: torch.Tensor, directions: torch.Tensor, centre: torch.Tensor, radius: float
                  ) -> torch.Tensor:
    """(R,3) where each ray first meets the sphere (centre, radius), or, for a ray that passes it by, its point
    nearest the centre (a ray through the hair beside a head meets the head's side there).

    >>> o = torch.tensor([[0.0, 0.0, 5.0], [2.0, 0.0, 5.0]]); d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    >>> sphere_points(o, d, torch.zeros(3), 1.0).tolist()
    [[0.0, 0.0, 1.0], [2.0, 0.0, 0.0]]
    """
    to_centre = centre - origins
    b = (to_centre * directions).sum(-1)
    c = to_centre.square().sum(-1) - radius * radius
    disc = b * b - c
    s = torch.where(disc >= 0, b - disc.clamp_min(0.0).sqrt(), b)
    return origins + s[:, None] * directions


@dataclass
class WholeGeometry:
    """A frame as each of the two sees it; the outside's made when a ray first needs it (a view within the captured
    cone never does)."""

    inside: PrimitivesGeometry
    outside_of: Callable[[], PrimitivesGeometry]
    centre: torch.Tensor = field(default_factory=lambda: torch.zeros(3))
    """The head's middle (world): the posed mesh's points above its lowest fifth, averaged."""
    radius: float = 0.1
    """The head's median distance from its middle (metres)."""
    device: torch.device | str | None = None
    _outside: PrimitivesGeometry | None = None

    @property
    def posed(self) -> torch.Tensor:
        return self.inside.posed

    @property
    def outside(self) -> PrimitivesGeometry:
        if self._outside is None:
            made = self.outside_of()
            self._outside = made if self.device is None else made.to(self.device)
        return self._outside

    def to(self, device: torch.device | str) -> WholeGeometry:
        return WholeGeometry(self.inside.to(device), self.outside_of, self.centre.to(device), self.radius, device,
                             None if self._outside is None else self._outside.to(device))


class WholeHeadAvatar(Avatar):
    name: ClassVar[str] = "whole"
    all_round: ClassVar[bool] = True
    normals_from_surface: ClassVar[bool] = True
    reads_raster: ClassVar[bool] = False
    quality_knobs: ClassVar[tuple[str, ...]] = PrimitivesAvatar.quality_knobs
    rays_per_step: ClassVar[int] = PrimitivesAvatar.rays_per_step
    frames_per_step: ClassVar[int] = PrimitivesAvatar.frames_per_step
    decode_ahead: bool = True
    """Where both parts render a frame, the outside decoded on a thread of its own beside the inside (outside_ahead);
    off, after it (benchmarks/bench_whole.py --poses compares the two)."""

    def __init__(self, inside: PrimitivesAvatar, outside: PriorAvatar):
        if inside.head_model.name != outside.head_model.name:
            raise ValueError(f"the inside is of the {inside.head_model.name} head model, the outside of the "
                             f"{outside.head_model.name}")
        super().__init__(inside.head_model, inside.n_frames, inside.background_colour())
        self.inside = inside
        self.outside = outside
        # The outside's display stops sooner (training composites every candidate), keeps its boxes within
        # OUTSIDE_STRETCH and, where the person has a body below the head (the inside's body layer: a video's
        # shoulders and clothes), fades its neck out under the chin (PrimitivesConfig.neck_fade). No frame saw that
        # body from behind: there the prior's neck came out as a stump in blocks of the collar's colours, ending in
        # its lowest boxes' faces. A capture with no body (a synthetic head, whose mesh is the whole person) keeps
        # the neck to the mesh's end: faded, the synthetic person's frames 45 to 180 degrees round lost 1.9-8.2 dB
        # (docs/results.md). The inside renders as its own folder does.
        outside.cfg = replace(outside.cfg, stop_below=max(outside.cfg.stop_below, OUTSIDE_STOP_BELOW),
                              stretch_at_most=OUTSIDE_STRETCH, neck_fade=inside.body is not None)
        with torch.no_grad():  # one room behind both: the inside's
            outside.background.copy_(inside.background)

    # ---- making and describing -------------------------------------------------------------------------
    @classmethod
    def for_capture(cls, head_model: HeadModel, n_frames: int, background: np.ndarray, effects: tuple[str, ...],
                    lighting: dict | None, config: Any = None) -> WholeHeadAvatar:
        raise ValueError("a whole-head avatar is two trained avatars: `train --model whole` trains both on a video")

    @classmethod
    def from_meta(cls, head_model: HeadModel, meta: dict) -> WholeHeadAvatar:
        return cls(PrimitivesAvatar.from_meta(head_model, meta["inside"]),
                   PriorAvatar.from_meta(head_model, meta["outside"]))

    def meta(self) -> dict:
        """Each part's own description (with its frames and background: what its from_meta reads) under `inside`
        and `outside`; what a checkpoint's avatar.json has at its top besides (head model, frames, views) is the
        inside's (the trainer's, or `compose`'s from the inside's folder)."""
        part = lambda m: {**m.meta(), "frames": m.n_frames, "background": m.background.tolist()}
        return {"model": self.name, "effects": list(self.effects), "inside": part(self.inside),
                "outside": part(self.outside),
                "blend": {"view_fade_deg": list(VIEW_FADE_DEG), "sweep_deg": SWEEP_DEG,
                          "facing_fade_deg": list(FACING_FADE_DEG), "seen_fade_deg": list(SEEN_FADE_DEG)}}

    @classmethod
    def buffer_names(cls, meta: dict) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The inside's normals (the rendered surface's, normals_from_surface: of the mixed depth, whatever either
        part has), and what else both parts make."""
        inside = PrimitivesAvatar.buffer_names(meta["inside"])
        outside = PriorAvatar.buffer_names(meta["outside"])
        return (tuple(b for b in inside[0] if b == "normals" or b in outside[0]),
                tuple(b for b in inside[1] if b in outside[1]))

    @property
    def effects(self) -> tuple[str, ...]:
        return self.inside.effects

    @property
    def plate(self):
        """The capture's room (the inside's): behind both parts."""
        return self.inside.plate

    @property
    def views(self):
        return self.inside.views

    @property
    def code_keys(self):
        """The inside's per-frame codes' keys (training goes on in the inside)."""
        return self.inside.code_keys

    def describe_rendering(self) -> str:
        return (f"whole head: inside the captured views {self.inside.describe_rendering()}; beyond them the "
                f"universal prior personalised")

    def describe_display(self) -> str:
        return self.inside.describe_display()

    def layout(self) -> dict[str, tuple[int, float | str]]:
        return self.inside.layout()

    @property
    def chunk_rays(self) -> int:
        return self.inside.chunk_rays

    @property
    def interactive_chunk_rays(self) -> int:
        return self.inside.interactive_chunk_rays

    # ---- per frame -------------------------------------------------------------------------------------
    def frame_geometry(self, controls: Controls, rasterizer: Rasterizer | None, time_s: float | None = None
                       ) -> WholeGeometry:
        inside = self.inside.frame_geometry(controls, rasterizer, time_s)
        posed = inside.posed
        # The head's middle: the mesh above its lowest fifth (a head model's neck and shoulders pull the box's
        # middle down towards the chin).
        low, high = posed[:, 1].min(), posed[:, 1].max()
        head = posed[posed[:, 1] > low + 0.2 * (high - low)]
        centre = head.mean(0)
        radius = float((head - centre).norm(dim=-1).median())
        return WholeGeometry(inside, lambda: self.outside.frame_geometry(controls, rasterizer, time_s), centre, radius)

    def image_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        return self.inside.image_pixels(camera, raster)

    def training_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        return self.inside.training_pixels(camera, raster)

    def note_views(self, frames) -> None:
        self.inside.note_views(frames)

    def fit_to_tracked_video(self, corrections: bool | None = None) -> None:
        self.inside.fit_to_tracked_video(corrections)

    def parameter_groups(self) -> list[dict]:
        """Training goes on in the inside (`train --resume`): the outside stays as personalised."""
        return self.inside.parameter_groups()

    def mesh_field(self, controls: Controls, rasterizer: Rasterizer | None) -> MeshField:
        return self.inside.mesh_field(controls, rasterizer)

    def before_save(self, geometry: WholeGeometry) -> None:
        self.inside.before_save(geometry.inside)

    # ---- rays ------------------------------------------------------------------------------------------
    def inside_weight(self, rays: Rays, geometry: WholeGeometry) -> torch.Tensor:
        """(R,) how much of each ray the inside renders (module docstring): 1 where the ray's camera stands within
        the captured cone (seen from the head's middle, as the inside's decoder reads its view); beyond, 1 where the
        ray meets the head where it faces into the cone widened by the camera's margin (SWEEP_DEG, shrinking over
        VIEW_FADE_DEG), falling to 0 over FACING_FADE_DEG beyond that, and all of it times the camera's fall over
        SEEN_FADE_DEG; 1 everywhere for an inside that kept no cone (a capture from all round)."""
        views = self.inside.views
        if views.axis is None:
            return rays.origins.new_ones(len(rays.origins))
        R = geometry.inside.rotation.to(rays.directions)  # head -> world: a world direction d is d @ R in the head's
        axis, cos_half = views.axis.to(rays.directions), float(views.cos)
        origins = rays.origins
        pinhole = len(origins) > 0 and bool((origins - origins[0]).abs().max() == 0)
        if pinhole:  # one camera: its view once, and a camera within the cone is all inside
            origins = origins[:1]
        towards = F.normalize(origins - geometry.inside.translation.to(origins), dim=-1)  # as view_of
        view = beyond_cone_deg(towards @ R, axis, cos_half)
        if pinhole and float(view[0]) <= 0.0:
            return rays.origins.new_ones(len(rays.origins))
        centre = geometry.centre.to(rays.origins)
        facing = F.normalize(sphere_points(rays.origins, rays.directions, centre, geometry.radius) - centre, dim=-1)
        side = beyond_cone_deg(facing @ R, axis, cos_half)
        margin = SWEEP_DEG * smooth_fall(view, *VIEW_FADE_DEG)
        seen = smooth_fall(side - margin, *FACING_FADE_DEG) * smooth_fall(view, *SEEN_FADE_DEG)
        return torch.where(view <= 0.0, 1.0, seen)

    def render_rays(self, rays: Rays, geometry: WholeGeometry, frame: int | None,
                    generator: torch.Generator | None = None, training: bool = False, options: Any = None
                    ) -> RayOutput:
        if training:  # training goes on in the inside (parameter_groups)
            return self.inside.render_rays(rays, geometry.inside, frame, generator, training=True, options=options)
        w = self.inside_weight(rays, geometry)
        w = torch.where(w >= 1.0 - EPS, 1.0, torch.where(w <= EPS, 0.0, w))  # a ray one part renders is all its
        idxs = [torch.nonzero(keep).squeeze(1) for keep in (w > 0.0, w < 1.0)]  # the inside's, the outside's
        sub = [rays[idx] if len(idx) else None for idx in idxs]
        ahead = self.outside_ahead(sub[1], geometry, options) \
            if self.decode_ahead and all(r is not None for r in sub) else None
        parts = []
        for outside, idx, code in ((False, idxs[0], frame), (True, idxs[1], None)):
            if len(idx) == 0:  # the outside's geometry is not even made
                parts.append((idx, None))
                continue
            if outside and ahead is not None:
                ahead.result()
            model, geo = self.part(outside, geometry)
            parts.append((idx, model.render_rays(sub[outside], geo, code, options=self.outside_options(options)
                                                 if outside else options)))
        return RayOutput(self.mixed(w, parts, ("rgb", "opacity", "depth"), lambda out: out.buffers),
                         (w, parts))

    def outside_ahead(self, rays: Rays, geometry: WholeGeometry, options: Any) -> Future | None:
        """Where both parts render rays of a frame, the outside's geometry and decode (for its `rays`) made on a
        thread of their own while the inside poses, decodes and marches (a decode is one thread's work: the other
        core stood idle); None where the outside's is made already or needs the GL rasterizer (its context is this
        thread's). The child's whole head in the studio's view posed by d3's frames, on two cores: 61-63 ms a frame
        (median) against 71-73 (`python -m benchmarks.bench_whole AVATAR --poses CAPTURE`)."""
        if geometry._outside is not None or self.outside.casts_shadows or not rays.origins.is_cpu:
            return None
        eye = rays.origins.mean(0)  # as the outside's render_rays takes it: its decode is found made
        outside_options = self.outside_options(options)
        inference = torch.is_inference_mode_enabled()  # grad modes are a thread's own

        def make() -> None:
            with torch.inference_mode(inference), torch.no_grad():
                self.outside.decoded(geometry.outside, None, eye, False, options=outside_options)

        return _AHEAD.submit(make)

    def outside_options(self, options: Any) -> Any:
        """The render options the outside renders with: at most the samples a segment it was trained with. More
        change nothing one can see (the child's whole head with its outside at the final preset's 16 against 8:
        55-58 dB apart at 30, 60 and 120 degrees) and cost a quarter of a frame's time where it renders most rays."""
        quality = getattr(options, "quality", None)
        if quality is None or quality.samples <= self.outside.cfg.samples:
            return options
        return replace(options, quality=replace(quality, samples=self.outside.cfg.samples))

    def part(self, outside: bool, geometry: WholeGeometry) -> tuple[PrimitivesAvatar, PrimitivesGeometry]:
        """One part and its geometry of the frame."""
        return (self.outside, geometry.outside) if outside else (self.inside, geometry.inside)

    @staticmethod
    def mixed(w: torch.Tensor, parts, names, buffers_of) -> dict[str, torch.Tensor]:
        """Each named buffer of the two parts' rays, mixed by the inside's weight w (R,): a ray one part alone
        rendered takes its value; a depth that one part leaves infinite (it drew nothing there) takes the other's."""
        alone = [part for _, part in parts if part is not None]
        if len(alone) == 1:  # one part rendered every ray (a view within the cone): its buffers as they are
            return {name: buffers_of(alone[0])[name] for name in names}
        out = {}
        for name in names:
            full = [None, None]
            for k, (idx, part) in enumerate(parts):
                if part is None:
                    continue
                value = buffers_of(part)[name]
                buf = value.new_zeros((len(w), *value.shape[1:]))
                buf[idx] = value
                full[k] = buf
            a, b = full
            ww = w.reshape(-1, *([1] * (a.dim() - 1))).to(a)
            if name == "depth":
                a = torch.where(torch.isfinite(a), a, b)
                b = torch.where(torch.isfinite(b), b, a)
            out[name] = ww * a + (1.0 - ww) * b
        return out

    def inspect(self, out: RayOutput, geometry: WholeGeometry, names: tuple[str, ...]) -> dict[str, torch.Tensor]:
        if not names:
            return {}
        w, parts = out.internals
        found = []
        for outside, (idx, part) in enumerate(parts):
            if part is None:
                found.append((idx, None))
                continue
            model, geo = self.part(bool(outside), geometry)
            found.append((idx, model.inspect(part, geo, names)))
        return self.mixed(w, found, names, lambda made: made)

    @property
    def trains_on_surface(self) -> bool:
        return self.inside.trains_on_surface

    def training_surface(self, raster) -> np.ndarray:
        return self.inside.training_surface(raster)

    def loss_terms(self, batch: TrainingBatch) -> dict[str, torch.Tensor]:
        return self.inside.loss_terms(replace(batch, geometry=batch.geometry.inside))
