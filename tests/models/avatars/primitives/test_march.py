"""The primitives' ray march: the tiled fast path against every-ray-against-every-primitive (the reference),
outputs and gradients; a hand-worked slab of known density; finite results on hard cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from models.avatars.primitives import march
from models.head.lbs import rotation_matrix_from_axis_angle
from render.camera import framing_camera
from render.rays import image_rays


def random_primitives(P: int = 40, M: int = 4, seed: int = 0, dtype=torch.float64) -> march.Primitives:
    g = torch.Generator().manual_seed(seed)
    centres = (torch.rand(P, 3, generator=g, dtype=dtype) - 0.5) * 0.2
    rot = rotation_matrix_from_axis_angle(torch.randn(P, 3, generator=g, dtype=dtype))
    half = 0.01 + 0.03 * torch.rand(P, 3, generator=g, dtype=dtype)
    density = 200 * torch.rand(P, M, M, M, generator=g, dtype=dtype)
    colour = torch.rand(P, M, M, M, 3, generator=g, dtype=dtype)
    return march.Primitives(centres, rot, half, density, colour)


def camera_rays(size: int = 24, yaw: float = 20.0, distance: float = 0.6, dtype=torch.float64):
    verts = np.array([[-0.12, -0.12, -0.12], [0.12, 0.12, 0.12]])
    cam = framing_camera(verts, yaw, 10.0, width_px=size, height_px=size)
    origin, dirs = image_rays(cam)
    dirs = dirs.to(dtype)
    return origin.to(dtype).expand(len(dirs), 3).contiguous(), dirs


def render(prims, origins, dirs, lists, samples=6, reference=False):
    """The fast path (tiled lists, grid_sample lookups); reference: every primitive on every list, gathered lookups."""
    bg = torch.tensor([0.2, 0.3, 0.4], dtype=origins.dtype)
    return march.march(origins, dirs, bg, prims, lists, samples, gather=march.trilinear if reference else None)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tiled_lists_render_what_every_primitive_renders(seed):
    prims = random_primitives(seed=seed)
    origins, dirs = camera_rays(yaw=30.0 * seed)
    fast = march.candidate_lists(origins, dirs, prims, rays_per_tile=16)
    every = march.every_primitive(origins, prims)
    assert fast.pairs < 0.6 * every.pairs  # the tiles do cull
    a, b = render(prims, origins, dirs, fast), render(prims, origins, dirs, every, reference=True)
    assert b.opacity.max() > 0.5 and (b.opacity < 1e-6).any()  # the image shows primitives and empty space
    torch.testing.assert_close(a.rgb, b.rgb, atol=1e-12, rtol=0)
    torch.testing.assert_close(a.opacity, b.opacity, atol=1e-12, rtol=0)
    assert a.samples == b.samples  # the same segments were sampled


def test_tiles_pair_a_primitive_about_the_eye_with_every_ray():
    prims = random_primitives(seed=3)
    origins, dirs = camera_rays()
    prims.centres[0] = origins[0] + 0.005
    prims.half_sizes[0] = 0.03
    a = render(prims, origins, dirs, march.candidate_lists(origins, dirs, prims, 16))
    b = render(prims, origins, dirs, march.every_primitive(origins, prims), reference=True)
    assert (a.opacity > 0.1).all()  # every ray starts inside it
    torch.testing.assert_close(a.rgb, b.rgb, atol=1e-12, rtol=0)


def test_gradients_match_the_reference():
    prims = random_primitives(P=12, M=3, seed=4)
    origins, dirs = camera_rays(size=12)
    grads = []
    for reference, pairs in ((False, march.candidate_lists(origins, dirs, prims, 8)),
                             (True, march.every_primitive(origins, prims))):
        d = prims.density.clone().requires_grad_(True)
        c = prims.colour.clone().requires_grad_(True)
        p = march.Primitives(prims.centres, prims.rotations, prims.half_sizes, d, c)
        out = render(p, origins, dirs, pairs, reference=reference)
        (out.rgb.square().sum() + out.opacity.sum()).backward()
        grads.append((d.grad, c.grad))
    torch.testing.assert_close(grads[0][0], grads[1][0], atol=1e-10, rtol=0)
    torch.testing.assert_close(grads[0][1], grads[1][1], atol=1e-10, rtol=0)
    assert grads[0][0].abs().sum() > 0


def test_one_pass_is_the_waves_with_nothing_stopped():
    """Training's one pass against the waves that display uses (one candidate a wave, three, eight), with a
    threshold no ray falls below: the same images and gradients."""
    prims = random_primitives(seed=8)
    origins, dirs = camera_rays()
    lists = march.candidate_lists(origins, dirs, prims, 16)
    bg = torch.tensor([0.2, 0.3, 0.4], dtype=origins.dtype)
    outs = []
    for stop, wave in ((0.0, 0), (1e-300, 1), (1e-300, 3), (1e-300, 8)):
        d = prims.density.clone().requires_grad_(True)
        p = march.Primitives(prims.centres, prims.rotations, prims.half_sizes, d, prims.colour)
        out = march.march(origins, dirs, bg, p, lists, 5, stop_below=stop, wave=wave)
        (out.rgb.square().sum() + out.depth.sum()).backward()
        outs.append((out, d.grad))
    (a, ga) = outs[0]
    assert int(lists.count.max()) > 8  # the waves of eight are more than one
    for b, gb in outs[1:]:
        assert a.segments == b.segments > 0
        for x, y in ((a.rgb, b.rgb), (a.opacity, b.opacity), (a.depth, b.depth), (ga, gb)):
            torch.testing.assert_close(x, y, atol=1e-10, rtol=0)


def test_packed_lookup_is_the_trilinear_reference():
    g = torch.Generator().manual_seed(5)
    values = torch.rand(7, 4, 4, 4, 3, generator=g, dtype=torch.float64)
    prim = torch.randint(7, (500,), generator=g)
    local = torch.rand(500, 3, generator=g, dtype=torch.float64) * 2.4 - 1.2  # beyond the box: its border
    want = march.trilinear(values, prim, local)
    prims = march.Primitives(torch.zeros(7, 3), torch.eye(3).expand(7, 3, 3), torch.ones(7, 3), values[..., 0],
                             values)
    o = torch.rand(500, 3, generator=g, dtype=torch.float64) * 2 - 1  # the points as rays o' + d' t
    t = torch.rand(500, 1, generator=g, dtype=torch.float64) + 0.5
    d = (local - o) / t
    for gather in (None, march.trilinear):
        lookups = march.Lookups(prims, gather)
        points = lookups.points(prim, o, d, march.SegmentSamples(torch.arange(500), t[:, 0], t[:, 0], 0))
        torch.testing.assert_close(lookups.colour(points), want, atol=1e-12, rtol=0)
        torch.testing.assert_close(lookups.density(points), want[:, 0], atol=1e-12, rtol=0)
        torch.testing.assert_close(lookups.colour(lookups.pick(points, torch.arange(5, 500, 7))),
                                   want[5::7], atol=1e-12, rtol=0)


def test_early_termination_changes_only_what_the_light_barely_reaches():
    prims = random_primitives(seed=6)
    prims.density.mul_(20)  # opaque: most rays end within their first segments
    origins, dirs = camera_rays()
    pairs = march.candidate_lists(origins, dirs, prims, 16)
    bg = torch.tensor([0.2, 0.3, 0.4], dtype=origins.dtype)
    full = march.march(origins, dirs, bg, prims, pairs, 6)
    for wave, saved in ((1, 0.7), (march.WAVE_CANDIDATES, 0.9)):  # the longer the waves, the later rays stop
        cut = march.march(origins, dirs, bg, prims, pairs, 6, stop_below=1e-3, wave=wave)
        assert cut.samples < saved * full.samples, (wave, cut.samples, full.samples)
        torch.testing.assert_close(cut.rgb, full.rgb, atol=2e-3, rtol=0)  # at most the light left (1e-3) x a colour


def test_colour_only_where_a_sample_shows_changes_a_pixel_by_at_most_the_weights_left_out():
    """Display looks the colour up only at samples whose weight reaches min_weight: each sample left out takes at
    most min_weight of a colour in [0,1] from its pixel, and most samples (empty space, what lies behind opaque
    matter) are left out."""
    prims = random_primitives(seed=6)
    prims.density.mul_(20)
    prims.density[prims.density < prims.density.median()] = 0.0  # empty space inside the boxes, as trained ones
    origins, dirs = camera_rays()
    pairs = march.candidate_lists(origins, dirs, prims, 16)
    bg = torch.tensor([0.2, 0.3, 0.4], dtype=origins.dtype)
    full = march.march(origins, dirs, bg, prims, pairs, 6)
    for min_weight in (1e-4, 1e-2):
        part = march.march(origins, dirs, bg, prims, pairs, 6, min_weight=min_weight)
        per_ray = int(pairs.count.max()) * 6  # samples a ray can have
        assert (part.rgb - full.rgb).abs().max() <= min_weight * per_ray
        torch.testing.assert_close(part.opacity, full.opacity, atol=1e-12, rtol=0)  # the density is all there
        assert part.samples < 0.8 * full.samples, (min_weight, part.samples, full.samples)


def test_one_slab_of_known_density_hand_worked():
    # One axis-aligned box, half-size 0.05 m, density 20 / m everywhere, colour (1, 0, 0); a ray along +z through
    # its middle crosses 0.1 m: opacity 1 - exp(-20 * 0.1) = 1 - e^-2 = 0.8647; rgb = 0.8647 red + 0.1353 background
    P, M = 1, 2
    prims = march.Primitives(torch.zeros(1, 3), torch.eye(3)[None], torch.full((1, 3), 0.05),
                             torch.full((P, M, M, M), 20.0), torch.tensor([1.0, 0, 0]).expand(P, M, M, M, 3))
    o, d = torch.tensor([[0.01, -0.02, -1.0]]), torch.tensor([[0.0, 0.0, 1.0]])
    bg = torch.tensor([0.0, 0.0, 1.0])
    out = march.march(o, d, bg, prims, march.every_primitive(o, prims), samples=5)
    want = 1 - math.exp(-2.0)
    torch.testing.assert_close(out.opacity, torch.tensor([want]))
    torch.testing.assert_close(out.rgb, torch.tensor([[want, 0.0, 1 - want]]))
    torch.testing.assert_close(out.depth, torch.tensor([1.0]), atol=0.02, rtol=0)  # the slab's middle, near enough


def test_the_light_outside_a_band_hand_worked():
    """The same slab (t from 0.95 to 1.05 along the ray), 5 samples at t = 0.96, 0.98, ..., 1.04, each 0.02 long:
    sample i's weight is e^(-0.4 i) (1 - e^-0.4). Band [0.97, 1.03]: the first and the last lie outside it, so
    off_band = (1 - e^-0.4)(1 + e^-1.6); a ray whose band is everything, or that meets nothing, has none. Its
    gradient reaches the density, and a march without a band keeps none."""
    P, M = 1, 2
    density = torch.full((P, M, M, M), 20.0, dtype=torch.float64, requires_grad=True)
    prims = march.Primitives(torch.zeros(1, 3, dtype=torch.float64), torch.eye(3, dtype=torch.float64)[None],
                             torch.full((1, 3), 0.05, dtype=torch.float64), density,
                             torch.tensor([1.0, 0, 0], dtype=torch.float64).expand(P, M, M, M, 3))
    o = torch.tensor([[0.01, -0.02, -1.0], [0.0, 0.0, -1.0], [0.5, 0.5, -1.0]], dtype=torch.float64)
    d = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64).expand(3, 3)
    inf = float("inf")
    band = (torch.tensor([0.97, -inf, 0.97], dtype=torch.float64), torch.tensor([1.03, inf, 1.03], dtype=torch.float64))
    out = march.march(o, d, torch.zeros(3, dtype=torch.float64), prims, march.every_primitive(o, prims), samples=5,
                      band=band)
    a = 1 - math.exp(-0.4)
    torch.testing.assert_close(out.off_band, torch.tensor([a * (1 + math.exp(-1.6)), 0.0, 0.0], dtype=torch.float64))
    out.off_band.sum().backward()
    assert torch.isfinite(density.grad).all() and float(density.grad.abs().sum()) > 0
    assert march.march(o, d, torch.zeros(3, dtype=torch.float64), prims.__class__(
        prims.centres, prims.rotations, prims.half_sizes, density.detach(), prims.colour),
        march.every_primitive(o, prims), samples=5).off_band is None


def test_hard_cases_stay_finite():
    """Primitives of zero size, rays along a face, densities of 0 and 1e6, the camera inside a primitive."""
    prims = random_primitives(P=20, M=4, seed=7, dtype=torch.float32)
    half = prims.half_sizes.clone()
    half[0] = 0.0  # collapsed
    half[1, 2] = 0.0  # flat
    density = prims.density.clone()
    density[2] = 1e6
    density[3] = 0.0
    centres = prims.centres.clone()
    origins, dirs = camera_rays(size=16, dtype=torch.float32)
    centres[4] = origins[0]  # the eye inside a primitive
    half[4] = 0.05
    # a ray exactly along a face of primitive 5 (axis-aligned): it grazes
    prims = march.Primitives(centres, prims.rotations, half, density, prims.colour)
    rot5 = torch.eye(3)
    prims.rotations[5] = rot5
    graze_o = (centres[5] + torch.tensor([-1.0, half[5, 1].item(), 0.0]))[None]
    origins = torch.cat([origins, graze_o])
    dirs = torch.cat([dirs, torch.tensor([[1.0, 0.0, 0.0]])])
    d = density.clone().requires_grad_(True)
    h = half.clone().requires_grad_(True)
    p = march.Primitives(centres, prims.rotations, h, d, prims.colour)
    band = (torch.full((len(origins),), 0.3), torch.full((len(origins),), 0.5))  # a face's band, on every ray
    out = march.march(origins, dirs, torch.zeros(3), p, march.candidate_lists(origins, dirs, p), 8, band=band)
    assert torch.isfinite(out.rgb).all() and torch.isfinite(out.opacity).all() and torch.isfinite(out.depth).all()
    assert torch.isfinite(out.off_band).all() and (out.off_band <= out.opacity + 1e-5).all()
    assert (out.opacity <= 1 + 1e-5).all()
    (out.rgb.sum() + out.depth.sum() + out.off_band.sum()).backward()
    assert torch.isfinite(d.grad).all() and torch.isfinite(h.grad).all()


def test_display_samples_follow_the_voxels_a_segment_crosses():
    """Display's adaptive samples (one a voxel crossed and one more, 8 at most) against the march with 256
    samples a segment (the integral, near enough): closer than 6 fixed samples a segment with no more lookups,
    and the tiled lists render what every primitive renders with them (no early stop: the waves differ)."""
    prims = random_primitives(P=40, M=8, seed=6)
    origins, dirs = camera_rays(size=32)
    bg = torch.tensor([0.2, 0.3, 0.4], dtype=origins.dtype)
    every = march.every_primitive(origins, prims)

    def run(samples, adaptive, lists=every, stop_below=1e-3):
        return march.march(origins, dirs, bg, prims, lists, samples, stop_below, min_weight=1e-4, adaptive=adaptive)

    truth, fixed, adaptive = run(256, False), run(6, False), run(8, True)
    assert truth.opacity.max() > 0.5
    assert adaptive.samples <= fixed.samples
    assert (adaptive.rgb - truth.rgb).abs().max() < 0.7 * (fixed.rgb - truth.rgb).abs().max()
    tiled = run(8, True, march.candidate_lists(origins, dirs, prims, rays_per_tile=16), stop_below=0.0)
    torch.testing.assert_close(tiled.rgb, run(8, True, stop_below=0.0).rgb, atol=1e-12, rtol=0)


def test_marching_in_parts_on_threads_renders_what_one_march_renders():
    prims = random_primitives(seed=7)
    origins, dirs = camera_rays(size=32, yaw=-20.0)
    bg = torch.rand(len(origins), 3, generator=torch.Generator().manual_seed(7), dtype=origins.dtype)
    threads = torch.get_num_threads()
    for stop, atol in ((0.0, 1e-12), (1e-3, 1e-3)):  # the groups' lists cut the waves elsewhere: early termination
        whole = march.march(origins, dirs, bg, prims, march.candidate_lists(origins, dirs, prims), 6, stop,
                            min_weight=march.DISPLAY_MIN_WEIGHT, adaptive=True)
        for parts in (2, 3):
            split = march.march_in_parts(origins, dirs, bg, prims, 6, stop, parts,
                                         min_weight=march.DISPLAY_MIN_WEIGHT, adaptive=True)
            assert abs(split.segments - whole.segments) <= 0.01 * whole.segments and whole.segments > 0
            for a, b in ((split.rgb, whole.rgb), (split.opacity, whole.opacity)):
                torch.testing.assert_close(a, b, atol=atol, rtol=0)
            assert torch.get_num_threads() == threads  # restored after the groups' one-thread marches


def test_display_keeps_opacity_and_depth_apart():
    """Display adds each wave into the image's sums in place: opacity (sum w, at most 1) and depth (sum w t over sum
    w, in metres along the ray) must each have a tensor of their own (they once shared one: opacity came out as
    sum w (1 + t) and the depth as 1 everywhere)."""
    prims = random_primitives(seed=8)
    origins, dirs = camera_rays(size=32, yaw=15.0)
    lists = march.candidate_lists(origins, dirs, prims)
    bg = torch.tensor([0.2, 0.3, 0.4], dtype=origins.dtype)
    with torch.inference_mode():
        shown = march.march(origins, dirs, bg, prims, lists, 6, 1e-3, min_weight=march.DISPLAY_MIN_WEIGHT)
    whole = march.march(origins, dirs, bg, prims, lists, 6)  # one pass, new tensors: the reference
    assert whole.opacity.max() > 0.9 and (shown.opacity <= 1 + 1e-9).all()
    torch.testing.assert_close(shown.opacity, whole.opacity, atol=1e-3, rtol=0)
    hit = whole.opacity > 0.5
    torch.testing.assert_close(shown.depth[hit], whole.depth[hit], atol=2e-3, rtol=0)



@pytest.mark.parametrize("along", [2, 0])
def test_windowed_boxes_show_no_edge_where_bare_boxes_do(along):
    """The blocks of a turntable (issue 34): two neighbouring boxes of one colour each (red, blue), half-size 25 mm,
    placed as the layout places neighbours (overlapping by 1.3), of uniform density 60 per metre (a ray through one
    box's middle: tau = 60 * 0.05 = 3, opacity 0.95). A row of rays 0.5 mm apart (1% of a box) crosses them, seen
    from the front (along z, the row along x: the outer faces and the seam) and from the side (along x, the row
    along y: top and bottom faces). Bare boxes show their faces: the opacity jumps by 0.95 or more between two
    neighbouring rays. With MVP's window on the density (as `opacity_window` makes it for the avatar) no two
    neighbouring rays differ by more than a fifth of that in opacity or colour, and a ray within 0.5 mm of a face
    lets four fifths of the light through where the bare boxes stop 95% of it (measured: 0.08 and 0.04 from the
    front, 0.17 from the side, where a ray crosses both boxes)."""
    from models.avatars.primitives.avatar import opacity_window

    M, h, sigma = 8, 0.025, 60.0
    gap = 2 * h / 1.3
    f64 = {"dtype": torch.float64}
    centres = torch.tensor([[-gap / 2, 0.0, 0.0], [gap / 2, 0.0, 0.0]], **f64)
    colour = torch.zeros(2, M, M, M, 3, **f64)
    colour[0, ..., 0] = 1.0
    colour[1, ..., 2] = 1.0
    bare = torch.full((2, M, M, M), sigma, **f64)
    row = 0 if along == 2 else 1  # the axis the rays are spread along
    d = torch.zeros(3, **f64)
    d[along] = 1.0
    xs = torch.arange(-0.07, 0.07, 0.0005, **f64)
    o = torch.zeros(len(xs), 3, **f64)
    o[:, row] = xs
    o = o - 0.5 * d
    dirs = d.expand(len(xs), 3).contiguous()
    faces = gap / 2 + h if row == 0 else h  # the outermost faces the row crosses
    near_face = (faces - xs.abs() > 0) & (faces - xs.abs() < 0.0005)
    got = {}
    for name, density in (("bare", bare), ("window", bare * opacity_window(M, bare))):
        prims = march.Primitives(centres, torch.eye(3, **f64).expand(2, 3, 3), torch.full((2, 3), h, **f64),
                                 density, colour)
        out = march.march(o, dirs, torch.zeros(3, **f64), prims, march.every_primitive(o, prims), samples=64)
        assert torch.isfinite(out.rgb).all()
        got[name] = (float(out.opacity.diff().abs().max()), float(out.rgb.diff(dim=0).abs().max()),
                     float(out.opacity[near_face].max()), float(out.opacity.max()))
    assert got["bare"][0] > 0.9 and got["bare"][1] > 0.9 and got["bare"][2] > 0.9  # the faces show
    assert got["window"][0] < 0.2 and got["window"][1] < 0.2 and got["window"][2] < 0.2, got["window"]
    assert got["window"][3] > 0.85  # the middle stays nearly as opaque as the bare boxes'
