"""The primitives' expression maps (`expression_maps`: Delta G in the decoder's own layout) and the trainer's
`--model-options` that switch them on: the map is zero at rest whatever the head's rigid pose, follows the jaw where
the mouth is, reaches only the slabs near it, and an avatar trained with it saves, reloads and renders the same."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from models.avatars.checkpoint import CheckpointError
from models.avatars.primitives.avatar import EXPRESSION_MAP_UNIT_M, PrimitivesAvatar, PrimitivesConfig
from models.avatars.primitives.decoder import SlabDecoder
from models.avatars.primitives.layout import ELEVATION_DEG
from models.avatars.rendering import render_image
from models.capture.frames import frame_camera
from models.head.controls import Controls
from models.ranges import OptionError
from models.training.trainer import TrainConfig, prepare_training
from render.gl.raster import Rasterizer
from tests.models.avatars.runs import photometric_before_and_after, saved_and_reloaded

MAPS = PrimitivesConfig(grid=16, voxels=4, width=16, expression_maps=True)


def jostle(decoder: torch.nn.Module) -> None:
    """Move every weight off its start (zero last layers, bias maps) so that every input reaches the output."""
    with torch.no_grad():
        for p in decoder.parameters():
            p.add_(0.05 * torch.randn_like(p))


def expression_map(avatar: PrimitivesAvatar, controls: Controls) -> torch.Tensor:
    return avatar.geometry(controls).expression[0]  # (3,S,S) centimetres


def test_the_map_is_zero_at_rest_and_follows_the_jaw(builtin_model):
    avatar = PrimitivesAvatar(builtin_model, MAPS, 1, np.zeros(3, np.float32))
    S = MAPS.grid * MAPS.voxels
    # the neutral face turned, tilted and moved: the rigid pose is taken out, nothing moved on the face
    root, move = np.array([0.3, -0.7, 0.2]), np.array([0.05, -0.02, 0.3])
    turned = Controls(root=root, translation=move)
    assert expression_map(avatar, turned).abs().max() < 1e-3  # centimetres: float32 rounding of a posed head
    # the jaw opened by 0.3 rad (17 degrees) on the same turned head
    opened = Controls(root=root, jaw=np.array([0.3, 0.0, 0.0]), translation=move)
    m = expression_map(avatar, opened).norm(dim=0)  # (S,S) how far each texel moved, cm
    # no texel moves farther than the farthest vertex (the texels are points of the mesh's triangles)
    v_rest, v_open = avatar.head.pose([Controls(), Controls(jaw=np.array([0.3, 0.0, 0.0]))])[0]
    most = float((v_open - v_rest).norm(dim=1).max()) / EXPRESSION_MAP_UNIT_M
    assert 0.5 * most < float(m.max()) <= most + 1e-3, (float(m.max()), most)
    # where: the texel that moved most is below the head's centre and in front (the chin), the crown did not move
    row, col = divmod(int(m.argmax()), S)
    elevation = ELEVATION_DEG[1] - (row + 0.5) / S * (ELEVATION_DEG[1] - ELEVATION_DEG[0])
    azimuth = -180.0 + (col + 0.5) / S * 360.0
    assert elevation < 0 and abs(azimuth) < 45, (elevation, azimuth)
    assert float(m[: S // 5].max()) < 0.01 * float(m.max())  # the top fifth of the chart's rows: the crown
    # an expression correction poses a frame's mesh again: its map is the corrected face's, whatever the root's turn
    smile = np.zeros(builtin_model.num_expression, np.float32)
    smile[:4] = [0.8, 0.8, 0.5, -0.3]
    as_given, corrected = avatar.geometry(turned), avatar.geometry(replace(turned, expression=smile))
    assert corrected.expression.abs().max() > 0.1
    torch.testing.assert_close(avatar.frame_expression_map(as_given, corrected.posed), corrected.expression,
                               atol=1e-3, rtol=0)


def test_geometry_maps_reach_only_the_slabs_near_them():
    dec = SlabDecoder(10, 6, grid=8, voxels=4, width=16, geometry_channels=3)
    jostle(dec)
    cond, gaze = torch.randn(1, 10), torch.zeros(1, 6)
    rest, moved = torch.zeros(1, 3, 32, 32), torch.zeros(1, 3, 32, 32)
    moved[..., :4, :4] = 1.0  # the first primitive's texels moved by a centimetre
    a, b = dec(cond, gaze, geometry=rest), dec(cond, gaze, geometry=moved)
    d = (a[0] - b[0]).abs().amax((1, 2, 3)) + (a[1] - b[1]).abs().amax((1, 2, 3, 4))  # (64,) per primitive
    assert d[0] > 1e-4  # the map changes the primitive it covers...
    assert d[63] == 0 and d[7] == 0 and d[56] == 0  # ...and not those of the other three corners
    with pytest.raises(AssertionError, match="geometry maps go with geometry_channels"):
        dec(cond, gaze)


def test_without_the_global_condition_the_controls_reach_the_slabs_only_through_the_map(builtin_model):
    smile = np.zeros(builtin_model.num_expression, np.float32)
    smile[:4] = [0.8, 0.8, 0.5, -0.3]
    a, b = Controls(expression=smile), Controls(jaw=np.array([0.3, 0.0, 0.0]))
    for global_expression in (True, False):
        torch.manual_seed(0)
        avatar = PrimitivesAvatar(builtin_model, replace(MAPS, global_expression=global_expression), 1,
                                  np.zeros(3, np.float32))
        jostle(avatar.decoder)
        width = avatar.decoder.fc.in_features
        geo_a, geo_b = avatar.geometry(a), avatar.geometry(b)
        rest = torch.zeros(1, MAPS.code_dim + 3)  # the code and the view
        own, other = (torch.cat([g.condition, rest], -1) for g in (geo_a, geo_b))
        slabs = [avatar.decode_slabs(geo_a, c, None, False, geo_a.posed) for c in (own, other)]
        same = all(torch.equal(x, y) for x, y in zip(*slabs, strict=True))
        if global_expression:  # the smile's frame decoded with the open jaw's weights: other slabs
            assert width == avatar.condition_dim + MAPS.code_dim + 3 and not same
        else:  # the weights are not read: the smile's map alone makes its slabs
            assert width == MAPS.code_dim + 3 and same
            other_map = avatar.decode_slabs(geo_b, own, None, False, geo_b.posed)
            assert not torch.equal(other_map[0], slabs[0][0])
    with pytest.raises(ValueError, match="global_expression false needs expression_maps true"):
        PrimitivesConfig(global_expression=False)


def test_gaze_at_the_eyes_leaves_the_back_of_the_head_as_it_was(builtin_model):
    looks = [Controls(gaze_left=np.array([0.0, y, 0.0]), gaze_right=np.array([0.0, y, 0.0])) for y in (0.0, 0.4)]
    for at_eyes in (False, True):
        torch.manual_seed(0)
        avatar = PrimitivesAvatar(builtin_model, replace(MAPS, gaze_at_eyes=at_eyes), 1, np.zeros(3, np.float32))
        jostle(avatar.decoder)
        ahead, turned = (avatar.geometry(c) for c in looks)
        assert not torch.equal(ahead.gaze, turned.gaze)
        geos = [ahead, replace(ahead, gaze=turned.gaze)]  # one mesh and map, the gaze alone turned
        condition = torch.cat([ahead.condition, torch.zeros(1, MAPS.code_dim + 3)], -1)
        with torch.no_grad():
            density = [avatar.decode_slabs(g, condition, None, False, g.posed)[0] for g in geos]
        change = (density[0] - density[1]).abs().amax((1, 2, 3)).reshape(MAPS.grid, MAPS.grid)
        back = torch.cat([change[:, :2], change[:, -2:]], 1)  # the chart's first and last columns: behind the head
        assert float(change.max()) > 1e-4  # the eyes' slabs follow the gaze either way
        assert (float(back.max()) == 0.0) == at_eyes, float(back.max())
    assert avatar.gaze_mask.sum() < 0.4 * avatar.gaze_mask.numel()  # the eyes and their neighbours, not the head


@pytest.mark.gl
def test_trained_with_expression_maps_saves_and_renders(synth_capture, gl, tmp_path):
    capture = synth_capture("studio", 12, 32)
    options = ("grid=8", "voxels=4", "width=16", "expression_maps=true")
    cfg = TrainConfig(dataset=capture, out=tmp_path / "maps", model="primitives", steps=60, checkpoint_seconds=1e9,
                      model_options=options)
    t = prepare_training(cfg, gl)
    assert t.avatar.cfg == PrimitivesConfig(grid=8, voxels=4, width=16, expression_maps=True)
    assert t.avatar.decoder.geometry_channels == 3
    first, last = photometric_before_and_after(t, 60)
    assert last < first / 2, (first, last)
    avatar, meta = saved_and_reloaded(t)
    assert meta["primitives"]["expression_maps"] is True and avatar.decoder.geometry_channels == 3
    f = t.split.frames[0]
    cam, r = frame_camera(t.split, f), Rasterizer(gl)
    np.testing.assert_array_equal(render_image(avatar, cam, f.controls, rasterizer=r)["rgb"],
                                  render_image(t.avatar, cam, f.controls, rasterizer=r)["rgb"])
    # the options are the new avatar's: a resumed one keeps its own, a bad one names itself
    with pytest.raises(CheckpointError, match="--model-options with --resume"):
        prepare_training(TrainConfig(dataset=capture, out=cfg.out, resume=True, model_options=options), gl)
    with pytest.raises(OptionError, match="--model-options grid=3: must be at least 8"):
        prepare_training(TrainConfig(dataset=capture, out=tmp_path / "bad", model="primitives",
                                     model_options=("grid=3",)), gl)
    with pytest.raises(OptionError, match="global_expression=false: global_expression false needs expression_maps"):
        prepare_training(TrainConfig(dataset=capture, out=tmp_path / "bad", model="primitives",
                                     model_options=("global_expression=false",)), gl)


def test_a_code_off_the_face_leaves_the_face_to_the_controls(builtin_model):
    """code_off_face: a per-frame code joins the decoder at K x K weighted by 1 - the share of each cell that the
    controls move; the slabs of cells whose neighbours up to two cells away all lie on the moving face (the furthest
    the upsamplings carry a K x K input: 1 + 1/2 + 1/4 + 1/8 cells) come out the same whatever the code, the crown's
    and the back's change. With the code in the global condition, every slab changes."""
    from models.avatars.primitives.chart import expression_share

    share = expression_share(builtin_model, 64, 16)[0, 0]
    assert float(share.max()) == 1.0 and float(share.min()) == 0.0  # a moving face and a still crown on the chart
    inner = F.max_pool2d((share < 1).float()[None, None], 5, stride=1, padding=2)[0, 0].flatten() == 0
    outer = (share == 0).flatten()
    assert int(inner.sum()) >= 4 and int(outer.sum()) >= 4
    for off_face in (True, False):
        torch.manual_seed(0)
        avatar = PrimitivesAvatar(builtin_model, replace(MAPS, code_off_face=off_face), 1, np.zeros(3, np.float32))
        jostle(avatar.decoder)
        geo = avatar.geometry(Controls())
        codes = torch.zeros(1, MAPS.code_dim), torch.randn(1, MAPS.code_dim)
        with torch.no_grad():
            slabs = [avatar.decode_slabs(geo, torch.cat([geo.condition, c, torch.zeros(1, 3)], -1), None, False,
                                         geo.posed)[0] for c in codes]
        change = (slabs[0] - slabs[1]).abs().flatten(1).amax(1)  # per cell of the K x K grid
        assert float(change[outer].min()) > 0  # the code still reaches the crown and the back
        if off_face:
            assert float(change[inner].max()) == 0.0
        else:
            assert float(change[inner].min()) > 0
    with pytest.raises(ValueError, match="code_off_face needs a per-frame code"):
        PrimitivesConfig(code_off_face=True, code_dim=0)
