"""Ray marching through volumetric primitives (MVP, Lombardi et al. 2021), as pure functions of tensors.

A frame's primitives are boxes (centre c, rotation R whose columns are the box's axes, half-sizes h) each holding an
M^3 voxel grid of density and colour. A ray meets a primitive over [t_in, t_out] (the slab test in the box's unit
frame); each such segment takes n samples at its midpoints, looked up trilinearly in that primitive's grid, and is
composited front to back (Eq. 1 of NeRF: w_i = T_i (1 - exp(-sigma_i delta_i))). The primitives are taken in one
order for every ray, nearest centre to the eye first (as splats are sorted), and each ray's samples within a
segment in order along it.

Which primitives a ray may meet (`CandidateLists`): `candidate_lists` bins the primitives' projected boxes into
screen tiles (the rays of a camera share an origin) and gives each ray its tile's list; `every_primitive` gives
every ray every primitive (the reference). Training marches every (ray, candidate) pair in one pass; display in
waves of a few candidates of every live ray at once (the slab test, then samples where they meet) and stops a ray
once it is opaque (early termination), so what lies behind the first surfaces is neither tested nor sampled.

This is the reference, in torch alone, on any device. native.py does display's march and training's lookups in C on
the CPU (tests hold the two together); dispatch.py chooses between them and says which ran.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from models.avatars.base import RenderCancelled

MAX_OPTICAL_DEPTH = 30.0
"""sigma * delta of one sample is clamped here (exp(-30) ~ 1e-13 of the light passes): a density of 1e6 per metre
stays finite in the running sums, and gradients beyond it are zero."""


@dataclass
class Primitives:
    """A frame's P primitives, each an M^3 grid."""

    centres: torch.Tensor  # (P,3) world, metres
    rotations: torch.Tensor  # (P,3,3) columns: the box's axes in world
    half_sizes: torch.Tensor  # (P,3) metres, along the box's axes
    density: torch.Tensor  # (P,M,M,M) per metre, indexed [z, y, x] of the box's axes
    colour: torch.Tensor  # (P,M,M,M,C): rgb in [0,1], then any channels composited alike (normals)

    def __post_init__(self):
        P = len(self.centres)
        assert self.rotations.shape == (P, 3, 3) and self.half_sizes.shape == (P, 3), (self.rotations.shape,)
        assert self.density.dim() == 4 and self.density.shape[0] == P, self.density.shape
        assert self.colour.shape[:4] == self.density.shape, (self.colour.shape, self.density.shape)

    def __len__(self) -> int:
        return len(self.centres)


@dataclass
class CandidateLists:
    """Each ray's candidate primitives: ray r's k-th is prims[start[r] + k] for k < count[r] (rays of one screen tile
    share a list), every list in the same front-to-back order."""

    prims: torch.Tensor  # (L,) primitive indices
    start: torch.Tensor  # (R,)
    count: torch.Tensor  # (R,)

    @property
    def pairs(self) -> int:
        return int(self.count.sum())


def front_to_back(origins: torch.Tensor, prims: Primitives) -> torch.Tensor:
    """(P,) the primitives by the distance of their centres from the rays' (mean) origin, nearest first."""
    eye = origins.mean(0) if len(origins) else torch.zeros(3, dtype=prims.centres.dtype)
    return torch.argsort((prims.centres - eye).norm(dim=1), stable=True)


def every_primitive(origins: torch.Tensor, prims: Primitives) -> CandidateLists:
    """Every ray with every primitive (the reference)."""
    R = len(origins)
    zeros = torch.zeros(R, dtype=torch.long, device=origins.device)
    return CandidateLists(front_to_back(origins, prims), zeros, zeros + len(prims))


def box_corners(prims: Primitives) -> torch.Tensor:
    """(P,8,3) the boxes' corners in world."""
    signs = torch.tensor([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=prims.centres.dtype,
                         device=prims.centres.device)
    local = signs[None] * prims.half_sizes[:, None]  # (P,8,3)
    return prims.centres[:, None] + local @ prims.rotations.transpose(1, 2)


def view_axes(fwd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Two unit axes across a unit view direction fwd (3,), at right angles to it and to each other: the first
    horizontal where fwd is not near vertical."""
    helper = torch.tensor([0.0, 1.0, 0.0], dtype=fwd.dtype, device=fwd.device)
    if (fwd @ helper).abs() > 0.9:
        helper = torch.tensor([1.0, 0.0, 0.0], dtype=fwd.dtype, device=fwd.device)
    a = torch.linalg.cross(helper, fwd)
    a = a / a.norm()
    return a, torch.linalg.cross(fwd, a)


def candidate_lists(origins: torch.Tensor, directions: torch.Tensor, prims: Primitives, rays_per_tile: int = 64
                    ) -> CandidateLists:
    """The primitives each ray may meet: rays of one pinhole (a shared origin) binned into screen tiles, each
    primitive's box projected (its corners' bounding rectangle) into the tiles it covers, each tile's list in
    `front_to_back` order. A superset of those that meet: the projection of a box in front of the eye lies within
    its corners' rectangle; a box reaching behind the eye (the camera inside or beside it) is on every list. Rays
    of many origins: every primitive."""
    R, P = len(origins), len(prims)
    if R == 0 or P == 0:
        return every_primitive(origins, prims)
    o = origins[0]
    fwd = directions.mean(0)
    if (origins - o).abs().max() > 1e-6 or fwd.norm() < 1e-6:
        return every_primitive(origins, prims)
    fwd = fwd / fwd.norm()
    a, b = view_axes(fwd)
    dz = directions @ fwd
    if dz.min() < 0.05:  # a field of view near 180 degrees: no plane to bin in
        return every_primitive(origins, prims)
    ray_xy = torch.stack([directions @ a, directions @ b], 1) / dz[:, None]  # (R,2)
    rel = box_corners(prims) - o  # (P,8,3)
    cz = rel @ fwd
    behind = (cz < 1e-4).any(1)  # (P,) reaches behind the eye: every ray
    cxy = torch.stack([rel @ a, rel @ b], -1) / cz.clamp_min(1e-4)[..., None]  # (P,8,2)
    lo, hi = cxy.min(1).values, cxy.max(1).values  # (P,2)
    # Tiles over the rays' own rectangle, about rays_per_tile rays each.
    r_lo, r_hi = ray_xy.min(0).values, ray_xy.max(0).values
    n = max(1, int((R / rays_per_tile) ** 0.5))
    size = (r_hi - r_lo).clamp_min(1e-9) / n
    ray_tile = ((ray_xy - r_lo) / size).floor().clamp(0, n - 1).long()
    ray_tile = ray_tile[:, 0] * n + ray_tile[:, 1]
    t0 = ((lo - r_lo) / size).floor().clamp(-1, n).long()
    t1 = ((hi - r_lo) / size).floor().clamp(-1, n).long()
    t0 = torch.where(behind[:, None], torch.zeros_like(t0), t0.clamp(0, n - 1))
    t1 = torch.where(behind[:, None], torch.full_like(t1, n - 1), t1.clamp(max=n - 1))
    visible = behind | ((hi >= r_lo) & (lo <= r_hi)).all(1)
    wx, wy = (t1[:, 0] - t0[:, 0] + 1).clamp_min(0), (t1[:, 1] - t0[:, 1] + 1).clamp_min(0)
    count = torch.where(visible, wx * wy, torch.zeros_like(wx))
    order = front_to_back(origins, prims)
    rank = torch.empty_like(order)
    rank[order] = torch.arange(P, device=o.device)
    prim_of = torch.repeat_interleave(torch.arange(P, device=o.device), count)
    local = torch.arange(len(prim_of), device=o.device) - torch.repeat_interleave(count.cumsum(0) - count, count)
    tx = t0[prim_of, 0] + torch.div(local, wy[prim_of].clamp_min(1), rounding_mode="floor")
    ty = t0[prim_of, 1] + local % wy[prim_of].clamp_min(1)
    tile = tx * n + ty
    by_tile = torch.argsort(tile * P + rank[prim_of])  # tile by tile, front to back within each
    tile_count = torch.bincount(tile, minlength=n * n)
    tile_start = tile_count.cumsum(0) - tile_count
    return CandidateLists(prim_of[by_tile], tile_start[ray_tile], tile_count[ray_tile])


@dataclass
class BoxFrames:
    """The primitives' unit frames, made once per march: to_box (P,9), the rows of R^T / h one after another, and
    where the rays share one origin, that origin in every box's frame (P,3)."""

    to_box: torch.Tensor
    eye: torch.Tensor | None


def box_frames(origins: torch.Tensor, prims: Primitives) -> BoxFrames:
    to_box = prims.rotations.transpose(1, 2) / prims.half_sizes.clamp_min(1e-9)[..., None]
    shared = len(origins) and bool((origins - origins[0]).abs().max() == 0)
    eye = (to_box @ (origins[0] - prims.centres)[..., None])[..., 0] if shared else None
    return BoxFrames(to_box.reshape(-1, 9), eye)


def in_box_frames(to_box: torch.Tensor, pair_prim: torch.Tensor, vectors: torch.Tensor) -> torch.Tensor:
    """(Q,3) vectors (Q,3) in the unit frames of primitives pair_prim (Q,) (to_box: BoxFrames.to_box): each row of
    a box's matrix gathered once and multiplied out column by column (a third of the time of gathering whole
    (Q,3,3) matrices and summing their products, on the demo avatar's 256 px march).

    >>> frames = box_frames(torch.zeros(1, 3), Primitives(torch.zeros(1, 3), torch.eye(3)[None], torch.tensor(
    ...     [[1.0, 2.0, 4.0]]), torch.zeros(1, 1, 1, 1), torch.zeros(1, 1, 1, 1, 3)))
    >>> in_box_frames(frames.to_box, torch.tensor([0]), torch.tensor([[1.0, 1.0, 1.0]]))
    tensor([[1.0000, 0.5000, 0.2500]])
    """
    rows = to_box.index_select(0, pair_prim)  # (Q,9)
    out = rows[:, 0::3] * vectors[:, :1]
    out.addcmul_(rows[:, 1::3], vectors[:, 1:2])
    return out.addcmul_(rows[:, 2::3], vectors[:, 2:3])


def ray_box_segments(origins: torch.Tensor, directions: torch.Tensor, prims: Primitives, pair_ray: torch.Tensor,
                     pair_prim: torch.Tensor, frames: BoxFrames | None = None
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The slab test of each pair (Q,): t_in, t_out (metres along the unit ray, t_in >= 0), whether they meet, and
    the ray in the box's unit frame, o' = R^T (o - c) / h and d' = R^T d / h (Q,3) (a point at t is o' + d' t
    there). An axis the ray runs parallel to (|d'| < 1e-9) is met everywhere or nowhere, by the sign of 1 - |o'|.
    frames: box_frames of these origins and primitives (made here if not given)."""
    frames = frames or box_frames(origins, prims)
    if frames.eye is not None:  # one pinhole: o' once a primitive
        o = frames.eye.index_select(0, pair_prim)
    else:
        o = in_box_frames(frames.to_box, pair_prim, origins.index_select(0, pair_ray)
                          - prims.centres.index_select(0, pair_prim))
    d = in_box_frames(frames.to_box, pair_prim, directions.index_select(0, pair_ray))
    parallel = d.abs() < 1e-9
    inverse = 1.0 / torch.where(parallel, torch.ones_like(d), d)
    ta, tb = (-1.0 - o) * inverse, (1.0 - o) * inverse
    lo = torch.where(parallel, torch.where(o.abs() <= 1.0, -torch.inf, torch.inf), torch.minimum(ta, tb))
    hi = torch.where(parallel, torch.where(o.abs() <= 1.0, torch.inf, -torch.inf), torch.maximum(ta, tb))
    t_in = lo.max(1).values.clamp_min(0.0)
    t_out = hi.min(1).values
    meet = t_out > t_in
    return t_in, torch.where(meet, t_out, t_in), meet, o, d


Gather = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]
"""A trilinear lookup with `trilinear`'s arguments and result: (values (P,M,M,M,C), prim (N,), local (N,3)) -> (N,C)."""


def trilinear(values: torch.Tensor, prim: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
    """(N,C) values (P,M,M,M,C) of primitives prim (N,) at box coordinates local (N,3) in [-1,1] (x, y, z of the
    box's axes; voxel centres at -1 + 2k/(M-1), clamped to the grid), trilinearly.

    >>> v = torch.arange(8.0).reshape(1, 2, 2, 2, 1)  # value 4z + 2y + x at the corners
    >>> trilinear(v, torch.tensor([0]), torch.tensor([[0.0, 0.0, 0.0], [1.0, -1.0, 0.5]]))[:, 0]
    tensor([3.5000, 4.0000])
    """
    P, M = values.shape[0], values.shape[1]
    flat = values.reshape(P * M * M * M, -1)
    g = ((local + 1.0) * 0.5 * (M - 1)).clamp(0, M - 1)
    i0 = g.floor().clamp(max=M - 2).long() if M > 1 else torch.zeros_like(g, dtype=torch.long)
    f = g - i0
    base = prim * (M * M * M)
    out = 0.0
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                if M == 1 and (dx or dy or dz):
                    continue
                idx = base + (i0[:, 2] + dz) * M * M + (i0[:, 1] + dy) * M + (i0[:, 0] + dx)
                w = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                     * (f[:, 2] if dz else 1 - f[:, 2])) if M > 1 else torch.ones_like(f[:, 0])
                out = out + w[:, None] * flat[idx]
    return out


def per_sample(x: torch.Tensor, seg: torch.Tensor, every: int) -> torch.Tensor:
    """x (S,...) of segments at each of their samples (N,...), the samples' segments seg (N,): repeated where every
    segment has `every` samples (a copy whose gradient is a sum: 13 ms a training step less than gathering, on 4096
    rays of the demo), else gathered."""
    if every:
        return x.unsqueeze(1).expand(-1, every, *x.shape[1:]).reshape(-1, *x.shape[1:])
    return x.index_select(0, seg)


@dataclass
class SegmentSamples:
    """The samples of S segments, segment by segment (N of them): each one's segment, midpoint t and step length."""

    seg: torch.Tensor  # (N,)
    t: torch.Tensor  # (N,)
    delta: torch.Tensor  # (N,)
    every: int  # the samples of every segment where all have as many (training), else 0

    def __len__(self) -> int:
        return len(self.seg)

    def of_segments(self, x: torch.Tensor) -> torch.Tensor:
        """x (S,...) of the segments at each sample (N,...)."""
        return per_sample(x, self.seg, self.every)

    def to_add(self, x: torch.Tensor) -> torch.Tensor:
        """Values x (N,...) of the samples as index_add adds them to their rays: summed within each segment where
        every segment has as many samples (S rows to add, not N, each to its segment's ray), else as they are (each
        to its sample's ray)."""
        return x.view(-1, self.every, *x.shape[1:]).sum(1) if self.every else x


def segment_samples(t_in: torch.Tensor, t_out: torch.Tensor, counts: torch.Tensor | int) -> SegmentSamples:
    """counts[q] (or `counts` each) equal steps over each segment q (Q,).

    >>> s = segment_samples(torch.tensor([0.0, 1.0]), torch.tensor([1.0, 2.0]), torch.tensor([4, 2]))
    >>> s.seg.tolist(), s.t.tolist(), s.delta.tolist()
    ([0, 0, 0, 0, 1, 1], [0.125, 0.375, 0.625, 0.875, 1.25, 1.75], [0.25, 0.25, 0.25, 0.25, 0.5, 0.5])
    >>> segment_samples(torch.tensor([0.0, 1.0]), torch.tensor([1.0, 2.0]), 2).t.tolist()
    [0.25, 0.75, 1.25, 1.75]
    """
    S, device, dtype = len(t_in), t_in.device, t_in.dtype
    if isinstance(counts, int):
        every, seg = counts, torch.arange(S, device=device).repeat_interleave(counts)
        k = torch.arange(counts, dtype=dtype, device=device).repeat(S)
        step = (t_out - t_in) / counts
    else:
        every, seg = 0, torch.repeat_interleave(torch.arange(S, device=device), counts)
        k = (torch.arange(len(seg), device=device) - (counts.cumsum(0) - counts).index_select(0, seg)).to(dtype)
        step = (t_out - t_in) / counts.clamp_min(1).to(dtype)
    delta = per_sample(step, seg, every)
    return SegmentSamples(seg, torch.addcmul(per_sample(t_in, seg, every), delta, k + 0.5), delta, every)


def voxel_counts(d_box: torch.Tensor, t_in: torch.Tensor, t_out: torch.Tensor, M: int, most: int) -> torch.Tensor:
    """(Q,) samples for each segment in display: one a voxel it crosses and one more, 2 at least, `most` at most.
    A segment's length in its box's unit frame is |d'| (t_out - t_in); the voxels' centres lie 2 / (M - 1) apart
    there. A ray straight through a box of 8^3 voxels crosses 7 spacings (8 samples); one that clips a corner,
    fewer: on the demo avatar at 256 px the segments' median crosses 5.4 spacings and the samples fall to 0.67 of
    8 a segment."""
    spacings = d_box.norm(dim=-1) * (t_out - t_in) * (0.5 * max(M - 1, 1))
    return (spacings.ceil().long() + 1).clamp(min(2, most), most)


def pack(values: torch.Tensor) -> torch.Tensor:
    """Primitives' grids (P,M,M,M,C) side by side along x as one volume (1,C,M,M,P*M) for `lookup`."""
    P, M, C = values.shape[0], values.shape[1], values.shape[-1]
    return values.permute(4, 1, 2, 0, 3).reshape(1, C, M, M, P * M)


def lookup(packed: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """The packed volume (1,C,M,M,P*M) at points (N,3) in its grid_sample coordinates (`Lookups.points` makes
    them, each inside its own primitive's grid, so no lookup blends two primitives), by one grid_sample. (N,C)."""
    out = F.grid_sample(packed, points.reshape(1, 1, 1, -1, 3), mode="bilinear", padding_mode="border",
                        align_corners=True)
    return out[0, :, 0, 0].T


@dataclass
class MarchOutput:
    rgb: torch.Tensor  # (R,3) over the background
    extra: torch.Tensor  # (R,C-3) the colour grids' other channels, composited (nothing behind them)
    opacity: torch.Tensor  # (R,)
    depth: torch.Tensor  # (R,) sum w t / sum w (0 where nothing)
    samples: int  # lookups made
    segments: int  # segments sampled
    off_band: torch.Tensor | None = None  # (R,) sum w over samples outside each ray's band (march's `band`)


DISPLAY_MIN_WEIGHT = 1e-4
"""Display looks up a sample's colour only where its compositing weight reaches this: a pixel loses at most this
much of its colour's range per sample left out (the samples of a ray number tens), far under 8 bits' step."""

WAVE_CANDIDATES = 4
"""Display marches each live ray's next this many candidates at once, then drops the rays that are opaque (early
termination by groups): fewer, larger operations than one candidate a wave, and a few more slab tests."""


def march(origins: torch.Tensor, directions: torch.Tensor, background: torch.Tensor, prims: Primitives,
          lists: CandidateLists, samples: int, stop_below: float = 0.0, gather: Gather | None = None,
          wave: int = WAVE_CANDIDATES, min_weight: float = 0.0, adaptive: bool = False,
          should_stop: Callable[[], bool] | None = None,
          band: tuple[torch.Tensor, torch.Tensor] | None = None) -> MarchOutput:
    """Composite the primitives along R rays (origins, directions (R,3), background (R,3) or (3,)), each through
    its candidate list in order, `samples` samples a segment. Without stop_below (training) every candidate in one
    pass; with stop_below > 0 (display) in waves of `wave` candidates of every live ray, and a ray takes no more
    once less than that share of its light gets through (early termination). min_weight > 0 (display): the
    density is looked up first, and the colour channels only at samples whose compositing weight reaches it (the
    others, empty space and what lies behind opaque matter, add less than that each). adaptive (display): a segment
    takes one sample a voxel it crosses and one more, `samples` at most (voxel_counts), where training takes
    `samples` on every segment. gather: the lookups by this trilinear function instead of grid_sample (`trilinear`:
    the reference's gathers). should_stop: asked before each wave; yes raises RenderCancelled (a newer request
    won). band (lo, hi) (R,) each: the output's off_band is each ray's compositing weight at samples whose t lies
    below lo or above hi (training's face depth: PrimitivesAvatar.loss_terms)."""
    R = len(origins)
    lookup_of = Lookups(prims, gather)
    frames = box_frames(origins, prims)
    dtype, device = prims.density.dtype, origins.device
    total = Composited.empty(R, prims.colour.shape[-1], dtype, device, band is not None)
    trans = torch.ones(R, dtype=dtype, device=device)
    longest = int(lists.count.max()) if R else 0
    step = max(1, longest) if stop_below <= 0 else max(1, wave)
    for k0 in range(0, longest, step):
        if should_stop is not None and should_stop():
            raise RenderCancelled
        live = lists.count > k0
        if stop_below > 0:
            live &= trans.detach() > stop_below
        r = torch.nonzero(live).squeeze(1)
        if len(r) == 0:
            break
        n = (lists.count[r] - k0).clamp(max=step)
        ray = torch.repeat_interleave(r, n)
        k = k0 + torch.arange(len(ray), device=device) - torch.repeat_interleave(n.cumsum(0) - n, n)
        total = composite_pairs(origins, directions, prims, lookup_of, frames, ray,
                                lists.prims[lists.start[ray] + k], samples, trans, total, min_weight, adaptive, band)
        trans = torch.exp(-total.optical_depth).to(dtype)
    depth = torch.where(total.opacity > 1e-10, total.depth / total.opacity.clamp_min(1e-10),
                        torch.zeros_like(total.depth))
    return MarchOutput(total.values[:, :3] + trans[:, None] * background, total.values[:, 3:], total.opacity, depth,
                       total.lookups, total.segments, total.off_band)


STRIPES = 16
"""march_in_parts deals each group this many bands of the screen."""

TASKS_PER_THREAD = 1
"""march_in_parts cuts the rays into this many groups a thread; a thread takes the next group when it is done with
one, so a thread that the window's drawing slows takes fewer."""


def stripe_groups(directions: torch.Tensor, groups: int) -> list[torch.Tensor]:
    """The rays' indices in `groups` groups of about equal work: the screen cut across the view into STRIPES bands
    a group, dealt round the groups in turn, so each group has a share of every part of the head.

    >>> [g.tolist() for g in stripe_groups(torch.tensor([[x / 10, 0.0, 1.0] for x in range(6)]), 3)]
    [[0, 3], [1, 4], [2, 5]]
    """
    R = len(directions)
    fwd = directions.mean(0)
    across = view_axes(fwd / fwd.norm().clamp_min(1e-12))[0]
    ray = torch.argsort(directions @ across)
    band = -(-R // (groups * STRIPES))
    group = torch.div(torch.arange(R, device=ray.device), band, rounding_mode="floor") % groups
    return [ray[group == k] for k in range(groups)]


def march_in_parts(origins: torch.Tensor, directions: torch.Tensor, background: torch.Tensor, prims: Primitives,
                   samples: int, stop_below: float, parts: int, **options) -> MarchOutput:
    """`march` of R rays in `parts` groups of about equal work, each on a thread of its own with one torch thread:
    the march is many small operations, which torch's own threads share out poorly (on two cores, 1.3x faster than
    two torch threads on one march: benchmarks/bench_primitives.py). The screen is cut across the view into
    STRIPES bands a group, dealt round the groups in turn, so each group has a share of every part of the head
    (halves of the demo's face at 256 px took 86 and 74 ms; 16 stripes a group, 74 and 76). The candidate lists
    are the whole image's. Each ray's result is what one march gives it. options: march's."""
    R = len(origins)
    lists = candidate_lists(origins, directions, prims)
    if parts <= 1 or R < 2 * parts:
        return march(origins, directions, background, prims, lists, samples, stop_below, **options)
    groups = stripe_groups(directions, parts * TASKS_PER_THREAD)
    ray = torch.cat(groups)
    grad, inference = torch.is_grad_enabled(), torch.is_inference_mode_enabled()

    def one(ray: torch.Tensor) -> MarchOutput:
        with torch.inference_mode(inference), torch.set_grad_enabled(grad):  # the caller's modes (thread-local)
            bg = background[ray] if background.dim() == 2 else background
            own = CandidateLists(lists.prims, lists.start[ray], lists.count[ray])
            return march(origins[ray], directions[ray], bg, prims, own, samples, stop_below, **options)

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with ThreadPoolExecutor(parts) as pool:
            outs = list(pool.map(one, groups))
    finally:
        torch.set_num_threads(threads)
    order = torch.empty_like(ray)
    order[ray] = torch.arange(R, device=ray.device)

    def joined(name: str) -> torch.Tensor:
        return torch.cat([getattr(out, name) for out in outs])[order]

    return MarchOutput(joined("rgb"), joined("extra"), joined("opacity"), joined("depth"),
                       sum(out.samples for out in outs), sum(out.segments for out in outs))


class Lookups:
    """The primitives' density (N,) and colour channels (N,C) at sample points: by one grid_sample on the grids
    packed side by side, or by `gather`, a trilinear lookup of the grids as they are (`trilinear`, the reference's
    gathers; or one that a caller passes in, as dispatch.py passes the C lookups). `points` places segments'
    samples in the coordinates the lookup reads."""

    def __init__(self, prims: Primitives, gather: Gather | None = None):
        self.gather = gather
        P, M = prims.density.shape[:2]
        if gather is not None:
            self.density_grid, self.colour_grid = prims.density[..., None], prims.colour
            return
        self.packed_density = pack(prims.density[..., None])
        self.packed_colour = pack(prims.colour)
        # box coordinates x in [-1, 1] of primitive p to the packed volume's: a x + b p + c along x (the
        # primitives side by side, voxel centres at align_corners' grid), y and z as they are
        span = max(P * M - 1, 1)  # the packed volume's width less one: align_corners' step is 2 / span
        self.scale = torch.tensor([(M - 1) / span, 1.0, 1.0], dtype=torch.float64, device=prims.density.device)
        self.shift = (2.0 * M / span, (M - 1) / span - 1.0)

    def points(self, prim: torch.Tensor, o_box: torch.Tensor, d_box: torch.Tensor, samples: SegmentSamples
               ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The samples of segments of primitives prim (S,) (rays o' + d' t in their boxes' unit frames (S,3)),
        clamped inside their boxes: their coordinates (N,3) (the packed volume's, or (gather) the boxes'), and
        (gather) each sample's primitive (N,); select samples with `pick`."""
        t = samples.t
        local = torch.addcmul(samples.of_segments(o_box), samples.of_segments(d_box), t[:, None]).clamp_(-1.0, 1.0)
        prim = samples.of_segments(prim)
        if self.gather is not None:
            return local, prim
        x = torch.addcmul(prim.to(t.dtype) * self.shift[0] + self.shift[1], local[:, 0], self.scale[0].to(t.dtype))
        return torch.cat([x[:, None], local[:, 1:]], 1), None

    @staticmethod
    def pick(points: tuple[torch.Tensor, torch.Tensor | None], index: torch.Tensor
             ) -> tuple[torch.Tensor, torch.Tensor | None]:
        coords, prim = points
        return coords[index], (prim[index] if prim is not None else None)

    def density(self, points: tuple[torch.Tensor, torch.Tensor | None]) -> torch.Tensor:
        coords, prim = points
        if self.gather is not None:
            return self.gather(self.density_grid, prim, coords)[:, 0]
        return lookup(self.packed_density, coords)[:, 0]

    def colour(self, points: tuple[torch.Tensor, torch.Tensor | None]) -> torch.Tensor:
        coords, prim = points
        if self.gather is not None:
            return self.gather(self.colour_grid, prim, coords)
        return lookup(self.packed_colour, coords)


@dataclass
class Composited:
    """What some segments of R rays add: colour channels, opacity and sum w t (each from the light that reaches
    them), the optical depth they put in the way (float64), the lookups and segments made, and (where the march has
    a band) the weight outside each ray's band."""

    values: torch.Tensor  # (R,C)
    opacity: torch.Tensor  # (R,)
    depth: torch.Tensor  # (R,)
    optical_depth: torch.Tensor  # (R,)
    lookups: int = 0
    segments: int = 0
    off_band: torch.Tensor | None = None  # (R,)

    @staticmethod
    def empty(R: int, channels: int, dtype: torch.dtype, device: torch.device | str, band: bool = False
              ) -> Composited:
        z = lambda: torch.zeros(R, dtype=dtype, device=device)  # a tensor each: display adds into them in place
        return Composited(torch.zeros(R, channels, dtype=dtype, device=device), z(), z(),
                          torch.zeros(R, dtype=torch.float64, device=device), off_band=z() if band else None)

    def added(self, value_ray: torch.Tensor, values: torch.Tensor, ray: torch.Tensor, opacity: torch.Tensor,
              depth: torch.Tensor, optical_depth: torch.Tensor, lookups: int, segments: int,
              off_band: tuple[torch.Tensor, torch.Tensor] | None = None) -> Composited:
        """These sums with values (V,C) added to rays value_ray (V,) and the segments' opacity, depth and optical
        depth (S,) to rays ray (S,), and off_band's weights (N,) to its rays (N,): in place where no gradient is
        recorded (display: a wave's few rays into the whole image's sums), else as new tensors (training's one
        pass)."""
        add = torch.Tensor.index_add if torch.is_grad_enabled() else torch.Tensor.index_add_
        off = self.off_band if off_band is None else add(self.off_band, 0, off_band[0], off_band[1])
        return Composited(add(self.values, 0, value_ray, values), add(self.opacity, 0, ray, opacity),
                          add(self.depth, 0, ray, depth), add(self.optical_depth, 0, ray, optical_depth),
                          self.lookups + lookups, self.segments + segments, off)


def composite_pairs(origins: torch.Tensor, directions: torch.Tensor, prims: Primitives, lookups: Lookups,
                    frames: BoxFrames, ray: torch.Tensor, prim: torch.Tensor, samples: int, trans: torch.Tensor,
                    total: Composited, min_weight: float = 0.0, adaptive: bool = False,
                    band: tuple[torch.Tensor, torch.Tensor] | None = None) -> Composited:
    """`total` (the sums of the rays' earlier segments) with the (ray, primitive) pairs (Q,) in order (ray by ray,
    each ray's front to back) composited over the light `trans` (R,) that reaches each ray's first: the slab test,
    `samples` samples a segment where they meet, laid out one after another ray by ray, each sample's light exp(-)
    the optical depth of its ray's samples before it here; the colour looked up only where a sample's weight
    reaches min_weight; adaptive: a segment takes one sample a voxel it crosses and one more, `samples` at most
    (voxel_counts); band (lo, hi) (R,): the weight of the samples outside their ray's [lo, hi] added to off_band."""
    t0, t1, meet, o_box, d_box = ray_box_segments(origins, directions, prims, ray, prim, frames)
    hit = torch.nonzero(meet).squeeze(1)
    ray, prim, o_box, d_box, t0, t1 = (x.index_select(0, hit) for x in (ray, prim, o_box, d_box, t0, t1))
    S = len(ray)
    counts = voxel_counts(d_box, t0, t1, prims.density.shape[1], samples) if adaptive else samples
    taken = segment_samples(t0, t1, counts)  # (N,) segment by segment, so ray by ray, front to back
    t, N = taken.t, len(taken)
    points = lookups.points(prim, o_box, d_box, taken)
    tau = (lookups.density(points).to(t.dtype) * taken.delta).clamp(0.0, MAX_OPTICAL_DEPTH)
    sample_ray = taken.of_segments(ray)
    # The light reaching each sample: exp(-) the optical depth of its ray's samples before it here, an exclusive
    # running sum (float64) less its value at the ray's first sample.
    before = tau.double().cumsum(0) - tau
    first = torch.ones(N, dtype=torch.bool, device=ray.device)
    first[1:] = sample_ray[1:] != sample_ray[:-1]
    begin = torch.where(first, torch.arange(N, device=ray.device), 0).cummax(0).values
    reach = taken.of_segments(trans.index_select(0, ray)) \
        * torch.exp(-(before - before.index_select(0, begin))).to(tau.dtype)
    w = reach * (1.0 - torch.exp(-tau))
    if min_weight > 0:  # each shown sample's colour straight onto its ray
        shows = torch.nonzero(w >= min_weight).squeeze(1)
        value_ray = sample_ray.index_select(0, shows)
        values = w.index_select(0, shows)[:, None] * lookups.colour(lookups.pick(points, shows)).to(tau.dtype)
        looked = len(shows)
    else:
        value_ray = ray if taken.every else sample_ray
        values, looked = taken.to_add(w[:, None] * lookups.colour(points).to(tau.dtype)), N
    off = None
    if band is not None:
        outside = (t < band[0].index_select(0, sample_ray)) | (t > band[1].index_select(0, sample_ray))
        off = (sample_ray, w * outside.to(w.dtype))
    return total.added(value_ray, values, ray if taken.every else sample_ray, taken.to_add(w), taken.to_add(w * t),
                       taken.to_add(tau.double()), N + looked, S, off)
