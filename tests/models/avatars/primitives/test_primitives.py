"""The volumetric-primitives avatar: its layout on every head model, the decoder's gaze apart from expression, a
tiny training run through the common trainer, its checkpoint and renders, and the display cache."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch

from models.avatars.base import RenderCancelled
from models.avatars.primitives.avatar import PrimitivesAvatar, PrimitivesConfig
from models.avatars.primitives.decoder import SlabDecoder
from models.avatars.primitives.layout import (
    ELEVATION_DEG,
    chart_azimuths,
    chart_directions,
    direction_caps,
    outermost_hits,
    primitive_layout,
    surface_frames,
)
from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, pixel_rays_of, render_image
from models.capture.frames import frame_camera
from models.head.controls import Controls
from models.head.flame import load_flame
from models.training.trainer import TrainConfig, prepare_training
from render.camera import framing_camera
from render.gl.raster import Rasterizer
from tests.conftest import DEMO
from tests.models.avatars.runs import (
    gpu_run_matches_cpu,
    photometric_before_and_after,
    saved_and_reloaded,
    with_frame_times,
)
from tests.models.head.flame_files import write_flame_from_head


def check_layout_on(model, grid: int = 16, covered: float = 0.78, front: float = 0.0) -> None:
    layout = primitive_layout(model, grid, front=front)
    assert layout.count > 0.5 * grid * grid  # the chart's cells mostly meet the head
    v = torch.as_tensor(model.template, dtype=torch.float64)
    tris = torch.as_tensor(np.asarray(model.triangles), dtype=torch.long)
    centres, rot = surface_frames(v, tris, torch.as_tensor(layout.triangles), torch.as_tensor(layout.bary))
    # each primitive sits on its triangle (barycentric point) and its frame is a rotation
    torch.testing.assert_close(rot.transpose(1, 2) @ rot, torch.eye(3, dtype=torch.float64).expand_as(rot),
                               atol=1e-9, rtol=0)
    torch.testing.assert_close(torch.linalg.det(rot), torch.ones(len(rot), dtype=torch.float64), atol=1e-9, rtol=0)
    extent = float(np.ptp(model.template, 0).max())
    assert (layout.half_size_m > 0).all() and layout.half_size_m.max() < 0.25 * extent
    # the outer surface: nine in ten primitives sit more than a fifth of the head's half-extent from its centre (a
    # few chart directions leave through an opening of the mesh, the neck's or the mouth's, from inside)
    centre = 0.5 * (v.min(0).values + v.max(0).values)
    radial = (centres - centre).norm(dim=1)
    assert (radial > 0.2 * extent / 2).double().mean() > 0.9
    # the boxes cover the surface: at least `covered` of the template's vertices (the hidden ones, inside the mouth
    # and eye sockets, need not be) lie in some primitive's box; sized to the cell alone, without the slant at which
    # the chart's ray leaves the surface, they left the neck below the chin bare (0.74 of the built-in head's, 0.89
    # of ICT's)
    half = torch.as_tensor(layout.half_size_m, dtype=torch.float64)
    inside = torch.zeros(len(v), dtype=torch.bool)
    for a in range(0, len(v), 2000):
        local = torch.einsum("pji,npj->npi", rot, v[a:a + 2000, None] - centres[None]) / half[None, :, None]
        inside[a:a + 2000] = (local.abs() <= 1).all(-1).any(1)
    assert inside.double().mean() >= covered, float(inside.double().mean())


def test_layout_on_every_head_model(builtin_model, ict_model, tmp_path):
    check_layout_on(builtin_model)
    check_layout_on(ict_model, covered=0.93)
    check_layout_on(load_flame(write_flame_from_head(tmp_path / "flame", builtin_model)))  # FLAME's file format
    # crowded to the face, its smaller boxes leave more of the mouth's and eyes' hidden insides out (0.92 of the
    # vertices); of the surface seen from the front and 30 degrees either side, open jaw or not, they hold 75-80%
    # (the shoulders below the chart are in those views) against 72-77% with even columns
    check_layout_on(ict_model, covered=0.9, front=2.0)


def test_layouts_are_computed_once_per_surface(builtin_model):
    """The layout and the chart are cached by the surface (HeadModel.surface_key), not by the model's name: the same
    surface read again gets the same arrays; a surface under the same name that differs gets its own (the layout of
    a head 10% larger has boxes 10% larger); an avatar's buffers are copies (loading weights into one leaves the
    shared layout as it was)."""
    from dataclasses import replace

    from models.avatars.primitives.chart import chart_sampler

    again = replace(builtin_model, template=builtin_model.template.copy())
    larger = replace(builtin_model, template=builtin_model.template * 1.1)
    assert again.surface_key == builtin_model.surface_key != larger.surface_key and larger.name == builtin_model.name
    assert primitive_layout(again, 8) is primitive_layout(builtin_model, 8)
    assert chart_sampler(again, 16) is chart_sampler(builtin_model, 16)
    np.testing.assert_allclose(primitive_layout(larger, 8).half_size_m, 1.1 * primitive_layout(builtin_model, 8)
                               .half_size_m, rtol=1e-5)
    assert not np.array_equal(chart_sampler(larger, 16).centre, chart_sampler(builtin_model, 16).centre)
    avatar = PrimitivesAvatar(builtin_model, PrimitivesConfig(grid=8, voxels=4), 1, np.zeros(3, np.float32))
    half = primitive_layout(builtin_model, 8, front=avatar.cfg.front).half_size_m.copy()
    avatar.layout_half.mul_(2.0)
    np.testing.assert_array_equal(primitive_layout(builtin_model, 8, front=avatar.cfg.front).half_size_m, half)


def test_a_chart_crowded_to_the_face_gives_it_smaller_primitives(ict_model):
    """front = 2: the columns within 50 degrees of the face hold twice the primitives, each about 0.6 times as wide
    (ICT, K = 16: 36 of 22.7 mm half-size against 72 of 13.5 mm), the back's grow; the even chart is front = 0."""
    def face(front: float):
        layout = primitive_layout(ict_model, 16, front=front)
        azimuth = np.degrees(chart_azimuths(16, front)[0])[layout.cells[:, 1]]
        elevation = ELEVATION_DEG[1] - (layout.cells[:, 0] + 0.5) / 16 * np.ptp(ELEVATION_DEG)
        on_face = (np.abs(azimuth) < 50) & (elevation > -40) & (elevation < 35)
        return on_face.sum(), np.median(layout.half_size_m[on_face]), layout.half_size_m.max()
    (n0, half0, back0), (n2, half2, back2) = face(0.0), face(2.0)
    assert n2 == 2 * n0 and 0.55 < half2 / half0 < 0.65 and back2 > back0, (n0, n2, half0, half2)


def test_tiled_chart_rays_hit_what_every_triangle_test_hits(builtin_model, ict_model):
    """outermost_hits' tiles of directions, each against the triangles whose caps reach it, give the same triangle,
    distance and barycentrics, bit for bit, as every ray against every triangle (ICT's 34k triangles at 16 x 16,
    the built-in head's at 48 x 48: its tiles hold 1-3 rays along the chart's rows there)."""
    for model, size in ((builtin_model, 48), (ict_model, 16)):
        verts, tris = np.asarray(model.template, np.float64), np.asarray(model.triangles, np.int64)
        centre = 0.5 * (verts.min(0) + verts.max(0))
        tiled = outermost_hits(centre, chart_directions(size), verts[tris])
        every = outermost_hits(centre, chart_directions(size), verts[tris], cull=False)
        assert (tiled[0] >= 0).mean() > 0.9
        for a, b in zip(tiled, every, strict=True):
            np.testing.assert_array_equal(a, b)
    # from inside a triangle's plane, or with a corner at the origin, the cap is everything: never culled
    _, radius = direction_caps(np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
                                         [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                         [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]]]))
    assert radius[0] == np.pi and radius[1] == np.pi and 0.5 < radius[2] < 0.6  # the last: 30.4 degrees


def test_gaze_enters_apart_from_expression():
    dec = SlabDecoder(10, 6, grid=8, voxels=4, width=16)
    with torch.no_grad():
        for p in dec.parameters():
            p.add_(0.05 * torch.randn_like(p))
    cond = torch.randn(1, 10)
    a = dec(cond, torch.zeros(1, 6))
    b = dec(cond, torch.tensor([[0.3, 0.0, 0.0, 0.3, 0.0, 0.0]]))
    assert a[0].shape == (64, 4, 4, 4) and a[1].shape == (64, 4, 4, 4, 3) and a[2].shape == (64, 9)
    assert (a[0] - b[0]).abs().max() > 1e-4  # gaze changes the slabs...
    shadowed = SlabDecoder(10, 6, grid=8, voxels=4, width=16, map_channels=1)
    with torch.no_grad():
        for p in shadowed.parameters():
            p.add_(0.05 * torch.randn_like(p))
    lit, dark = torch.ones(1, 1, 32, 32), torch.ones(1, 1, 32, 32)
    dark[..., :4, :4] = 0.0  # the first primitive's texels in shadow
    d = (shadowed(cond, torch.zeros(1, 6), lit)[1] - shadowed(cond, torch.zeros(1, 6), dark)[1]).abs()
    assert d[0].max() > 1e-4  # the map changes the primitive it covers...
    assert d[63].max() == 0  # ...and not one far from it (the last upsampling's and the slab's 3x3 reach)
    dec.offsets.weight.data.zero_()
    dec.offsets.bias.data.zero_()
    assert dec(cond, torch.zeros(1, 6))[2].abs().max() == 0  # ...and offsets start at zero


SMALL = PrimitivesConfig(grid=8, voxels=4, width=16)


def test_kept_size_primitives_never_shrink_below_their_places(builtin_model):
    """keep_size: a decoder asking every primitive to shrink to e^-0.5 of its size (the offsets' scale channels)
    leaves them at their layout size, where without it they take e^-0.5 of it; one asking them to grow gets its way
    with or without. The volume prior then has nothing below the layout to pull towards: its gradient there is 0."""
    from dataclasses import replace

    for keep, scale in ((False, -0.5), (True, -0.5), (True, 0.25)):
        avatar = PrimitivesAvatar(builtin_model, replace(SMALL, keep_size=keep), 1, np.zeros(3, np.float32))
        with torch.no_grad():
            avatar.decoder.offsets.weight.zero_()
            avatar.decoder.offsets.bias.zero_()
            avatar.decoder.offsets.bias[6:9] = scale
        geo = avatar.geometry(Controls())
        prims, offsets = avatar.decode(geo, avatar.codes(0), torch.tensor([0.0, 0.0, 1.0]), training=True)
        assert float(offsets[:, 6:9].detach().sub(scale).abs().max()) < 1e-6
        want = avatar.layout_half[:, None] * float(np.exp(scale) if scale > 0 or not keep else 1.0)
        torch.testing.assert_close(prims.half_sizes, want.expand(-1, 3))
        (prims.half_sizes.prod(1) / avatar.layout_half.pow(3)).mean().backward()  # the volume prior
        pull = float(avatar.decoder.offsets.bias.grad[6:9].abs().max())
        assert (pull == 0.0) == (keep and scale < 0), (keep, scale, pull)


def test_primitives_stretch_at_most_as_told(builtin_model):
    """stretch_at_most: a decoder asking every primitive to grow 7.4 times (e^2) along its first axis, 1.5 times
    along its second and to shrink to 0.8 along its third is shown (3 x 0.8, 1.5, 0.8) of its place's size under a
    limit of 3 (a whole head's outside's: whole/avatar.py OUTSIDE_STRETCH), what it asks for without; training's
    decode keeps what it asks for either way; one asking to grow 7.4 times evenly gets that either way."""
    from dataclasses import replace

    uneven = [2.0, float(np.log(1.5)), float(np.log(0.8))]
    asks = ((uneven, 3.0, False, [2.4, 1.5, 0.8]), (uneven, None, False, [np.exp(2.0), 1.5, 0.8]),
            (uneven, 3.0, True, [np.exp(2.0), 1.5, 0.8]), ([2.0, 2.0, 2.0], 3.0, False, [np.exp(2.0)] * 3))
    for scales, stretch, training, want in asks:
        avatar = PrimitivesAvatar(builtin_model, replace(SMALL, stretch_at_most=stretch), 1, np.zeros(3, np.float32))
        with torch.no_grad():
            avatar.decoder.offsets.weight.zero_()
            avatar.decoder.offsets.bias.zero_()
            avatar.decoder.offsets.bias[6:9] = torch.tensor(scales)
            prims, _ = avatar.decode(avatar.geometry(Controls()), avatar.codes(0), torch.tensor([0.0, 0.0, 1.0]),
                                     training=training)
        torch.testing.assert_close(prims.half_sizes, avatar.layout_half[:, None] * torch.tensor(want).float())


@pytest.mark.gl
def test_tiny_primitives_run(synth_capture, gl, tmp_path):
    capture = synth_capture("studio", 16, 32)
    cfg = TrainConfig(dataset=capture, out=tmp_path / "pr", model="primitives", steps=80, checkpoint_seconds=1e9)
    t = prepare_training(cfg, gl, SMALL)
    first, last = photometric_before_and_after(t, 80)
    assert last < first / 2, (first, last)
    avatar, meta = saved_and_reloaded(t)
    assert isinstance(avatar, PrimitivesAvatar) and meta["model"] == "primitives"
    f = t.split.frames[0]
    cam = frame_camera(t.split, f)
    r = Rasterizer(gl)
    out = render_image(avatar, cam, f.controls, rasterizer=r)
    again = render_image(avatar, cam, f.controls, rasterizer=r)
    assert out["rgb"].shape == (32, 32, 3) and np.isfinite(out["rgb"]).all() and out["opacity"].max() > 0.5
    # `all` effects: the normals buffer, from the opacity grids' gradients, is unit where the head is opaque
    assert avatar.needs_normals and avatar.light_dir is not None
    lengths = np.linalg.norm(out["normals"], axis=-1)[out["opacity"] > 0.99]
    assert len(lengths) and np.median(lengths) > 0.5 and lengths.max() < 1.0 + 1e-4
    np.testing.assert_array_equal(out["rgb"], again["rgb"])
    # `shadows` on a capture with a key light: the decoder reads the light's visibility of every texel, in the slab's
    # layout (primitive at grid cell (i, j), texel (y, x) at image pixel (i M + y, j M + x)), from the shadow map
    geo = avatar.frame_geometry(f.controls, r)
    assert avatar.casts_shadows and geo.light is not None
    from models.avatars.primitives.layout import surface_frames as frames_of
    centres, rot = frames_of(geo.posed, avatar.triangles, avatar.layout_triangles, avatar.layout_bary)
    image = avatar.slab_visibility(geo, centres, rot)[0, 0]
    K, M = avatar.cfg.grid, avatar.cfg.voxels
    for p in (0, len(centres) // 2, len(centres) - 1):
        i, j = divmod(int(avatar.layout_cells[p]), K)
        for y, x in ((0, 0), (M - 1, 1), (2, M - 1)):
            point = centres[p] + avatar.layout_half[p] * ((-1 + 2 * x / (M - 1)) * rot[p, :, 0]
                                                          + (-1 + 2 * y / (M - 1)) * rot[p, :, 1])
            assert abs(float(image[i * M + y, j * M + x]) - float(geo.light.visibility(point[None])[0])) < 1e-5
    assert image.min() < 0.5 < image.max()  # some texels in the head's own shadow, some lit
    inspected = render_image(avatar, cam, f.controls, RenderOptions(inspect=True), r)
    light = inspected["rgb_light"]
    assert light.shape == (32, 32, 3) and light.min() >= 0 and light.max() <= 1
    assert (light[out["opacity"] < 1e-3] > 1 - 1e-3).all()  # no head: nothing casts a shadow there
    # without cast shadows: the decode with every texel lit, marched along the same rays (another image)
    np.testing.assert_array_equal(inspected["rgb"], out["rgb"])
    assert inspected["rgb_no_shadows"].shape == (32, 32, 3) and np.isfinite(inspected["rgb_no_shadows"]).all()
    assert np.abs(inspected["rgb_no_shadows"] - out["rgb"]).max() > 1e-4
    # Display decodes once a frame: a frame's batches of rays share its decode.
    geo = avatar.frame_geometry(f.controls, r)
    rays, _ = pixel_rays_of(avatar, geo, cam, r)
    with torch.inference_mode():
        avatar.render_rays(rays[:50], geo, None)
        cached = geo.decoded[False, ("rgb_light",)]
        avatar.render_rays(rays[50:], geo, None)
        assert geo.decoded[False, ("rgb_light",)] is cached
        assert cached[0].colour.shape[-1] == 3 + 1  # the normals are the surface's (render_image), not composited
    # A render makes the buffers asked for alone: the colour render composites rgb, 3 of the grids' 4 channels,
    # and gives the same pixels.
    plain = render_image(avatar, cam, f.controls, RenderOptions(buffers=()), r)
    assert "normals" not in plain and "normals" in out
    np.testing.assert_array_equal(plain["rgb"], out["rgb"])
    colour_only = RenderOptions(buffers=())
    extras = avatar.shown_channels(options=colour_only)
    assert extras == () and avatar.shown_channels(lit=True, options=colour_only) == ()
    with torch.inference_mode():
        decoded = avatar.decode(geo, avatar.codes(None, geo.code_weights), rays.origins[0], extras=extras)
        assert decoded[0].colour.shape[-1] == 3
    r.release()
    # A new expression changes the render (the decoder reads the controls).
    expression = f.controls.with_expression(avatar.head_model, {avatar.head_model.expr_names[0]: 1.0})
    moved = render_image(avatar, cam, expression, rasterizer=Rasterizer(gl))
    assert np.abs(moved["rgb"] - out["rgb"]).max() > 1e-3


@pytest.mark.gl
def test_a_newer_request_stops_a_frame_within_its_one_batch(gl):
    """The studio renders a primitives frame in one batch of rays: render_image's should_stop reaches the march,
    which asks it between waves (in every group), so a newer request need not wait for the whole frame."""
    avatar, _ = load_avatar(DEMO)
    raster = Rasterizer(gl)
    cam = framing_camera(avatar.card.rest_vertices(), 20, 5, fov_y_deg=18.0, width_px=96, height_px=96)
    controls = avatar.card.at_rest(Controls())
    asked = []

    def after_three() -> bool:
        asked.append(1)
        return len(asked) > 3

    with pytest.raises(RenderCancelled):
        render_image(avatar, cam, controls, RenderOptions(should_stop=after_three, cores=2,
                                                          chunk_rays=avatar.interactive_chunk_rays), raster)
    assert len(asked) > 3  # the one batch's check, then the waves'
    assert not hasattr(avatar, "should_stop")  # the render's own, never set on the avatar
    asked.clear()
    options = RenderOptions(should_stop=lambda: bool(asked.append(1)), cores=2,
                            chunk_rays=avatar.interactive_chunk_rays)
    image = render_image(avatar, cam, controls, options, raster)["rgb"]
    assert len(asked) > 3 and image.shape == (96, 96, 3)  # asked between waves, and never told to stop
    again = render_image(avatar, cam, controls, rasterizer=raster)["rgb"]
    torch.testing.assert_close(torch.as_tensor(image), torch.as_tensor(again))
    raster.release()


@pytest.mark.gl
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (--device cuda); torch sees none here")
def test_cuda_trains_and_renders_as_the_cpu_does(synth_capture, gl, tmp_path):
    """`train --device cuda`: the same steps (same seed and rays) give the same losses and weights to float
    tolerance, with every effect, expression maps, the opacity window and kept sizes on (the capture with frame
    times, so that the codes' choice renders on the GPU too); a render on the GPU (the
    torch march) matches the CPU's (the C march where a compiler is found: within 2e-3 of the torch march, tests of
    test_native.py)."""
    options = ("grid=8", "voxels=4", "width=16", "expression_maps=true", "opacity_window=true", "keep_size=true")
    capture = with_frame_times(synth_capture("sun", 12, 32), tmp_path / "timed")
    gpu_run_matches_cpu(TrainConfig(dataset=capture, out=tmp_path / "cpu", model="primitives",
                                    steps=4, checkpoint_seconds=1e9, model_options=options), gl, 0.5,
                        ("rgb", "normals", "opacity"))


def test_opacity_fades_where_the_capture_never_looked(synth_capture, tmp_path, gl):
    """A capture whose frames cut the head at the chin (its principal point moved 40% of the frame down: the lower
    head and neck project below every frame): the texels there get no opacity (seen_fade 0), those inside the
    frames keep all of it (1), with a ramp between; rendered whole from the front, the avatar shows nothing below
    the cut where without the fade its untrained primitives stood, and the same pixels above it."""
    from app.cli import main

    capture = tmp_path / "cut"
    shutil.copytree(synth_capture("ambient", 12, 32), capture)
    for split in ("train", "val", "test"):
        path = capture / f"transforms_{split}.json"
        meta = json.loads(path.read_text())
        fx, fy, cx, cy = meta["intrinsics"]
        meta["intrinsics"] = [fx, fy, cx, cy + 0.4 * meta["height"]]
        path.write_text(json.dumps(meta))
    assert main(["train", str(capture), "--out", str(tmp_path / "av"), "--model", "primitives", "--steps", "2",
                 "--rays-per-step", "64"]) == 0
    avatar, _ = load_avatar(tmp_path / "av")
    fade = avatar.seen_fade
    assert float(fade.min()) == 0.0 and float(fade.max()) == 1.0
    assert bool(((fade > 0.05) & (fade < 0.95)).any())  # a ramp, not a cut
    cam = framing_camera(avatar.card.rest_vertices(), fov_y_deg=18.0, width_px=48, height_px=48)
    r = Rasterizer(gl)
    controls = avatar.card.at_rest(Controls())
    faded = render_image(avatar, cam, controls, RenderOptions(buffers=()), r)
    del avatar.seen_fade
    whole = render_image(avatar, cam, controls, RenderOptions(buffers=()), r)
    r.release()
    # rows' largest opacity, measured: whole 1 down to row 37 (0.68 in 38), faded 0.97, 0.45, then 0 from row 33
    lower, upper = slice(34, 38), slice(0, 24)
    assert whole["opacity"][lower].max(1).min() > 0.9 and faded["opacity"][lower].max() < 0.05
    np.testing.assert_allclose(faded["rgb"][upper], whole["rgb"][upper], atol=2e-3)


def test_an_avatar_from_before_the_fade_resumes_and_fades_nothing(synth_capture, tmp_path):
    """A checkpoint without seen_fade (trained before it came: made here by taking the key out of a fresh one's
    weights) resumes: the trainer notes the views, which makes the buffer, and the load then drops it, as a plain
    load of that checkpoint has none."""
    from safetensors.torch import load_file, save_file

    from app.cli import main

    capture = synth_capture("ambient", 12, 24)
    out = tmp_path / "av"
    assert main(["train", str(capture), "--out", str(out), "--model", "primitives", "--steps", "2",
                 "--rays-per-step", "64"]) == 0
    (weights,) = out.glob("weights-*.safetensors")
    tensors = load_file(weights)
    assert "seen_fade" in tensors
    del tensors["seen_fade"]
    save_file(tensors, weights)
    assert "seen_fade" not in load_avatar(out)[0].state_dict()
    assert main(["train", str(capture), "--out", str(out), "--steps", "3", "--resume", "--rays-per-step", "64"]) == 0
    assert "seen_fade" not in load_avatar(out)[0].state_dict()


def test_the_face_depth_term_keeps_the_face_on_the_tracked_surface(synth_capture, gl, tmp_path):
    """face_depth > 0: training keeps each frame's distance to the guide mesh on the face's pixels alone (the
    triangles face_vertices marks, but the eyeballs'; inf on the crown and off the head), as a raster of the frame
    gives it; the loss
    has the term, and trained with it the share of the face rays' light composited more than face_margin_m off
    the mesh falls below what the same steps without it leave. face_depth 0: no distances kept. (The eyeballs
    are not the face's surface here: the lids cover them.)"""
    from dataclasses import replace

    from models.avatars.primitives.chart import GAZE_JOINTS, carried_by, face_vertices
    from models.training.trainer import TrainingBatch

    capture = synth_capture("studio", 16, 48)
    plain = prepare_training(TrainConfig(dataset=capture, out=tmp_path / "plain", model="primitives", steps=1,
                                         checkpoint_seconds=1e9), gl, SMALL)
    assert plain.frames.surface_t is None and not plain.avatar.trains_on_surface
    cfg = replace(SMALL, face_depth=1.0)
    t = prepare_training(TrainConfig(dataset=capture, out=tmp_path / "fd", model="primitives", steps=1,
                                     checkpoint_seconds=1e9), gl, cfg)
    assert t.avatar.trains_on_surface and t.frames.surface_t is not None
    head = t.avatar.head_model
    face = (face_vertices(head) & ~carried_by(head, GAZE_JOINTS))[np.asarray(head.triangles)].all(1)
    r = Rasterizer(gl)
    for k in (0, 7):
        f = t.split.frames[k]
        raster = r.rasterize(t.frames.geometry[k].posed.cpu().numpy(), head.triangles, frame_camera(t.split, f))
        on = (raster.triangle >= 0) & face[np.maximum(raster.triangle, 0)]
        kept = t.frames.surface_t[k].float().numpy()
        assert t.frames.surface_t.dtype == torch.float16  # half precision: the face's depth needs no more
        assert on.sum() > 100 and ((raster.triangle >= 0) & ~on).sum() > 20  # face, and head that is not face
        np.testing.assert_array_equal(np.isfinite(kept), on)
        np.testing.assert_allclose(kept[on], raster.distance[on], rtol=1e-3)
    r.release()

    def off_share(trainer) -> float:
        """The face rays' light more than the margin off the mesh, on frame 3's face pixels."""
        fs = trainer.frames
        pick = torch.from_numpy(np.flatnonzero(np.isfinite(t.frames.surface_t[3].float().numpy().ravel())))
        rays = fs.rays(3, pick)
        rays = type(rays)(rays.origins, rays.directions, t.frames.surface_t[3].reshape(-1)[pick].float(),
                          rays.background)
        with torch.no_grad():
            out = trainer.avatar.render_rays(rays, fs.geometry[3], 3, training=True,
                                             band=t.avatar.face_band(rays))
        return float(out.internals[2].off_band.mean())

    terms = t.avatar.loss_terms(TrainingBatch(3, t.frames.rays(3, torch.arange(48 * 48)), torch.zeros(48 * 48, 3),
                                              t.frames.geometry[3], 0.0, torch.Generator().manual_seed(0)))
    assert "face_depth" in terms and 0 < float(terms["face_depth"].detach()) < 1.0
    torch.manual_seed(0)
    without = prepare_training(TrainConfig(dataset=capture, out=tmp_path / "w0", model="primitives", steps=150,
                                           checkpoint_seconds=1e9), gl, SMALL)
    torch.manual_seed(0)
    with_term = prepare_training(TrainConfig(dataset=capture, out=tmp_path / "w1", model="primitives", steps=150,
                                             checkpoint_seconds=1e9), gl, cfg)
    for trainer in (without, with_term):
        for _ in range(150):
            trainer.train_step(0.5)
    assert cfg.face_margin_m == 0.02
    shares = off_share(with_term), off_share(without)
    print("face light off the surface, with the term and without:", shares)
    assert shares[0] < 0.7 * shares[1], shares
