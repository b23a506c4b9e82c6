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
