"""The primitives' body layer (components/body.py) in the avatar: behind the primitives and over the plate along the
capture camera's rays, standing at the neck and moving with it, nothing in any other camera, kept with the
weights."""

from __future__ import annotations

import numpy as np
import torch

from models.avatars.components.body import EXTENT_M
from models.avatars.primitives.avatar import PrimitivesAvatar, PrimitivesConfig
from models.avatars.rendering import RenderOptions, render_image
from models.head.controls import Controls
from render.camera import framing_camera, project

RED, BLUE = (0.9, 0.1, 0.1), (0.1, 0.1, 0.9)


def two_colour_avatar(head_model) -> PrimitivesAvatar:
    """A tiny primitives avatar with a body layer: its upper half opaque red, its lower half opaque blue (the
    boundary 0.15 m below the neck: EXTENT_M's top 0.3 less half its 0.9)."""
    torch.manual_seed(0)
    cfg = PrimitivesConfig(grid=8, voxels=4, width=16, body_layer=True)
    avatar = PrimitivesAvatar(head_model, cfg, 2, np.zeros(3, np.float32))
    with torch.no_grad():
        texels = avatar.body.texels
        avatar.body.texture[:, 3] = 20.0
        for rows, colour in ((slice(0, texels // 2), RED), (slice(texels // 2, None), BLUE)):
            avatar.body.texture[0, :3, rows] = torch.logit(torch.tensor(colour))[:, None, None]
    return avatar


def test_the_body_layer_shows_behind_the_head_in_the_capture_camera_and_follows_the_neck(builtin_model):
    avatar = two_colour_avatar(builtin_model)
    _, _, bottom, top = EXTENT_M
    assert abs(0.5 * (top - bottom) - (top + 0.15)) < 1e-9
    cam = framing_camera(builtin_model.template, 0.0, 0.0, fov_y_deg=30.0, width_px=48, height_px=48, zoom=0.6)
    plate = np.full((48, 48, 3), 0.5, np.float32)
    avatar.plate.note(plate, cam)
    for lift in (0.0, 0.03):  # the head and its neck 3 cm higher: the boundary moves up with them
        controls = Controls(translation=np.array([0.0, lift, 0.0], np.float32))
        out = render_image(avatar, cam, controls, RenderOptions(buffers=()))
        neck, axes = avatar.geometry(controls).body
        assert torch.equal(axes, torch.eye(3))  # no turn: the head model's own axes
        u, v, _ = project(cam, (neck.numpy() + [0.0, -0.15, 0.0])[None].astype(np.float64))
        boundary = float(v[0])  # the row, in pixels from the top, where red meets blue
        clear = out["opacity"] < 1e-3  # the primitives draw nothing: the layer (or the plate) shows
        column = round(float(u[0]))
        rgb = out["rgb"][:, column]
        above = [y for y in range(48) if clear[y, column] and y < boundary - 1]
        below = [y for y in range(48) if clear[y, column] and y > boundary + 1]
        assert len(below) >= 3, below
        np.testing.assert_allclose(rgb[below], np.broadcast_to(BLUE, (len(below), 3)), atol=2e-3)
        np.testing.assert_allclose(rgb[above], np.broadcast_to(RED, (len(above), 3)), atol=2e-3)
        assert not np.any(np.all(np.abs(out["rgb"][clear] - 0.5) < 1e-3, -1))  # the plate is covered everywhere
    # Another camera has no plate, and so no layer: the background colour where the primitives draw nothing.
    other = framing_camera(builtin_model.template, 40.0, 0.0, fov_y_deg=30.0, width_px=48, height_px=48, zoom=0.6)
    out = render_image(avatar, other, Controls(), RenderOptions(buffers=()))
    clear = out["opacity"] < 1e-3
    assert clear.mean() > 0.3
    np.testing.assert_allclose(out["rgb"][clear], 0.0, atol=1e-6)


def test_the_body_layer_is_kept_with_the_weights(builtin_model):
    avatar = two_colour_avatar(builtin_model)
    seen = np.zeros((avatar.body.texels,) * 2, bool)
    seen[:10] = True
    avatar.body.note_seen(seen)
    again = PrimitivesAvatar(builtin_model, avatar.cfg, 2, np.zeros(3, np.float32))
    again.load_state_dict(avatar.state_dict())
    assert torch.equal(again.body.texture, avatar.body.texture) and torch.equal(again.body.source, avatar.body.source)
    assert int(again.body.source[-1]) == 9 * avatar.body.texels + avatar.body.texels - 1  # the seen texel above
    groups = avatar.parameter_groups()
    assert [g["lr_scale"] for g in groups][-1] > 1.0 and groups[-1]["params"] == [avatar.body.texture]
    assert sum(len(g["params"]) for g in groups) == len(list(avatar.parameters()))


def test_texels_no_training_ray_reaches_show_the_taught_ones_not_their_start(builtin_model, tmp_path):
    """note_body counts the texels whose centres fall on pixels training draws rays from (FrameSet.active_index),
    not every pixel of the frame: here training draws from the image's left half alone. A texel whose centre only
    the right half shows (the room far from the person, in a video) then shows its nearest taught texel's values;
    taught clear, the room shows through it exactly, where its own untaught start (START_OPACITY_LOGIT) would lay a
    haze over it."""
    from models.avatars.components.body import START_OPACITY_LOGIT
    from models.capture.dataset import CaptureSplit, Frame
    from models.training.data import FrameSet
    from render.rays import image_rays

    torch.manual_seed(0)
    avatar = PrimitivesAvatar(builtin_model, PrimitivesConfig(grid=8, voxels=4, width=16, body_layer=True), 1,
                              np.zeros(3, np.float32))
    cam = framing_camera(builtin_model.template, 0.0, 0.0, fov_y_deg=30.0, width_px=48, height_px=48, zoom=0.6)
    frame = Frame(0, tmp_path / "0.png", np.linalg.inv(cam.view), np.zeros(0), Controls())
    split = CaptureSplit(tmp_path, "train", "avatar-studio", 48, 48, cam.intrinsics, "builtin", np.zeros(0),
                         np.zeros(3), None, [frame])
    avatar.plate.note(np.zeros((48, 48, 3), np.float32), cam)  # a tracked video's room: the layer shows
    left = torch.as_tensor(np.flatnonzero(np.arange(48 * 48) % 48 < 24).astype(np.int32))
    geo = avatar.geometry(Controls())
    frames = FrameSet(split, torch.zeros(1, 48, 48, 3, dtype=torch.uint8), torch.zeros(3), torch.zeros(1, 3),
                      torch.zeros(48 * 48, 3), torch.eye(3, dtype=torch.float64)[None], None, [geo], [left])
    avatar.note_body(frames)
    # Where each texel's centre lies in the image, by the pinhole worked here (camera looks down -z).
    T = avatar.body.texels
    at = avatar.body.texel_centres(geo.body).double().numpy() @ cam.view[:3, :3].T + cam.view[:3, 3]
    fx, fy, cx, cy = cam.intrinsics
    col, row = cx + fx * at[:, 0] / -at[:, 2], cy - fy * at[:, 1] / -at[:, 2]
    in_image = (col >= 0) & (col < 48) & (row >= 0) & (row < 48)
    taught = (in_image & (col < 24)).reshape(T, T)
    only_right = (in_image & (col >= 24)).reshape(T, T)
    assert taught.sum() > 100 and only_right.sum() > 100
    own = torch.arange(T * T).reshape(T, T)
    source = avatar.body.source.reshape(T, T)
    assert torch.equal(source[taught], own[taught])  # a taught texel shows itself
    assert not bool((source[only_right] == own[only_right]).any())
    assert bool(taught.reshape(-1)[avatar.body.source].all())  # every texel shows a taught one
    origin, directions = image_rays(cam)
    right = torch.as_tensor(np.arange(48 * 48) % 48 >= 27)
    room = torch.rand(48 * 48, 3)
    with torch.no_grad():
        assert abs(float(avatar.body.texture[0, 3, 0, 0]) - START_OPACITY_LOGIT) < 1e-9
        hazy = avatar.body.over(room, origin.expand_as(directions), directions, geo.body)
        assert (hazy[right] - room[right]).abs().max() > 5e-3  # before any teaching: the start's haze
        avatar.body.texture[0, 3][torch.as_tensor(taught)] = -30.0  # the loss taught the room's texels clear
        shown = avatar.body.over(room, origin.expand_as(directions), directions, geo.body)
    np.testing.assert_allclose(shown[right].numpy(), room[right].numpy(), atol=1e-6)


def test_the_rows_below_the_mesh_train_only_where_the_capture_has_a_plate(builtin_model, gl):
    """Training draws rays from every row below the mesh's lowest for the body layer only where the frames' rays
    carry a plate (a tracked video's room): a capture with a background colour never shows the layer."""
    from render.gl.raster import Rasterizer

    avatar = two_colour_avatar(builtin_model)
    cam = framing_camera(builtin_model.template, 0.0, 0.0, fov_y_deg=30.0, width_px=48, height_px=48, zoom=0.5)
    raster = Rasterizer(gl)
    cover = raster.coverage(builtin_model.template, builtin_model.triangles, cam)
    raster.release()
    lowest = int(np.nonzero(cover.hit.any(1))[0].max())
    assert lowest < 40
    assert not avatar.shows_body
    plain = avatar.training_pixels(cam, cover)
    assert plain[lowest].any() and not plain[-1].any()  # the mesh's neighbourhood alone
    avatar.plate.note(np.zeros((48, 48, 3), np.float32), cam)
    assert avatar.shows_body
    with_plate = avatar.training_pixels(cam, cover)
    partial = ~with_plate.all(1)  # the rows above the band: as without the plate
    assert with_plate[lowest:].all() and partial.sum() >= 16 and np.array_equal(with_plate[partial], plain[partial])
