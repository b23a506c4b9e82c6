"""The body layer (models/avatars/components/body.py): where rays meet its plane, what it composites, the texels it
fills from the seen ones, its texels' centres, and that the loss reaches its texture."""

import math

import numpy as np
import torch

from models.avatars.components.body import EXTENT_M, FILL_BLUR, START_OPACITY_LOGIT, BodyLayer, body_frame

FACING_CAMERA = (torch.tensor([0.0, -0.1, -1.0]), torch.eye(3))  # the neck 1 m ahead of a camera at the origin


def test_a_ray_meets_the_plane_where_worked_by_hand():
    layer = BodyLayer(texels=8)
    origins = torch.zeros(4, 3)
    # straight ahead (the neck's point); 0.2 m right and 0.3 m down at 1 m; along the plane; away from it
    directions = torch.nn.functional.normalize(torch.tensor(
        [[0.0, -0.1, -1.0], [0.2, -0.4, -1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), dim=-1)
    xy, hit = layer.plane_coordinates(origins, directions, FACING_CAMERA)
    left, right, bottom, top = EXTENT_M
    assert hit.tolist() == [True, True, False, False]
    expected = [[2 * (0.0 - left) / (right - left) - 1, 2 * (top - 0.0) / (top - bottom) - 1],
                [2 * (0.2 - left) / (right - left) - 1, 2 * (top + 0.3) / (top - bottom) - 1]]
    torch.testing.assert_close(xy[:2], torch.tensor(expected), atol=1e-6, rtol=0)


def test_the_plane_turns_with_the_body():
    """A body turned 90 degrees about the vertical faces the camera edge on: a ray straight at the neck grazes the
    plane and misses it; turned 60 degrees, the same ray meets the plane at the neck's own point (the middle
    column)."""
    layer = BodyLayer(texels=8)
    turn = lambda deg: torch.tensor([[math.cos(math.radians(deg)), 0, math.sin(math.radians(deg))], [0, 1.0, 0],
                                     [-math.sin(math.radians(deg)), 0, math.cos(math.radians(deg))]])
    centre = torch.tensor([0.0, 0.0, -1.0])
    ahead = torch.tensor([[0.0, 0.0, -1.0]])
    _, hit = layer.plane_coordinates(torch.zeros(1, 3), ahead, (centre, turn(90.0)))
    assert not bool(hit[0])
    xy, hit = layer.plane_coordinates(torch.zeros(1, 3), ahead, (centre, turn(60.0)))
    assert bool(hit[0])  # straight at the neck: the neck's own point
    left, right, _, _ = EXTENT_M
    assert abs(float(xy[0, 0]) - (2 * (0.0 - left) / (right - left) - 1)) < 1e-6


def test_it_composites_over_the_plate_and_is_clear_where_it_starts():
    layer = BodyLayer(texels=8)
    plate = torch.tensor([[0.2, 0.4, 0.6], [0.2, 0.4, 0.6]])
    origins = torch.zeros(2, 3)
    directions = torch.nn.functional.normalize(torch.tensor([[0.0, -0.1, -1.0], [1.0, 0.0, 0.0]]), dim=-1)
    start = layer.over(plate, origins, directions, FACING_CAMERA)
    a = 1.0 / (1.0 + math.exp(-START_OPACITY_LOGIT))
    torch.testing.assert_close(start[0], a * 0.5 + (1 - a) * plate[0], atol=1e-6, rtol=0)
    torch.testing.assert_close(start[1], plate[1])  # a ray along the plane: the plate alone
    with torch.no_grad():
        layer.texture[:, :3] = torch.logit(torch.tensor([0.9, 0.1, 0.3]))[None, :, None, None]
        layer.texture[:, 3] = 20.0
    torch.testing.assert_close(layer.over(plate, origins, directions, FACING_CAMERA)[0],
                               torch.tensor([0.9, 0.1, 0.3]), atol=1e-5, rtol=0)


def test_unseen_texels_show_their_nearest_seen_ones_averaged():
    """Seen: the top half of 12 x 12 texels. Each texel of the bottom half takes the seen texel straight above it
    (the clothes go on below the lowest edge a training frame showed), then the mean of those over FILL_BLUR
    texels a side (cut at the texture's edges), worked here by loops; the seen texels keep their own values."""
    T = 12
    layer = BodyLayer(texels=T)
    values = np.random.default_rng(0).random((T, T))
    with torch.no_grad():
        layer.texture[0, 0] = torch.as_tensor(values)
    seen = np.zeros((T, T), bool)
    seen[:6] = True
    layer.note_seen(seen)
    filled = values.copy()
    filled[6:] = values[5]
    half = FILL_BLUR // 2
    shown = layer.shown()[0, 0].detach().numpy()
    for y in range(T):
        for x in range(T):
            window = filled[max(y - half, 0):y + half + 1, max(x - half, 0):x + half + 1]
            want = values[y, x] if y < 6 else window.mean()
            assert abs(shown[y, x] - want) < 1e-6, (y, x)
    layer.note_seen(np.ones((T, T), bool))  # everything seen: the texture as it is
    np.testing.assert_array_equal(layer.shown()[0, 0].detach().numpy(), values.astype(np.float32))


def test_the_texels_centres_and_the_loss_reaching_the_texels_a_ray_meets():
    layer = BodyLayer(texels=16)
    left, right, bottom, top = EXTENT_M
    neck = torch.tensor([0.0, -0.1, -1.0])
    turn = torch.tensor([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # x along -z: turned 90 degrees
    centres = layer.texel_centres((neck, turn)).reshape(16, 16, 3)
    # texel (row 4, column 8): (left + 8.5 / 16 * 0.9, top - 4.5 / 16 * 0.9) in the plane, along x -> -z, y -> y
    u, v = left + 8.5 / 16 * (right - left), top - 4.5 / 16 * (top - bottom)
    torch.testing.assert_close(centres[4, 8], neck + torch.tensor([0.0, v, -u]), atol=1e-6, rtol=0)
    # a ray through a texel's centre meets the plane there: texture coordinates at the texel's centre
    at = layer.texel_centres(FACING_CAMERA).reshape(16, 16, 3)[4, 8]
    xy, hit = layer.plane_coordinates(torch.zeros(1, 3), torch.nn.functional.normalize(at, dim=0)[None],
                                      FACING_CAMERA)
    assert bool(hit[0])
    torch.testing.assert_close(xy[0], torch.tensor([2 * 8.5 / 16 - 1, 2 * 4.5 / 16 - 1]), atol=1e-5, rtol=0)
    ys = torch.linspace(-0.05, -0.3, 20)  # rays into the upper middle of the plane
    directions = torch.nn.functional.normalize(torch.stack([torch.zeros(20), ys, -torch.ones(20)], -1), dim=-1)
    out = layer.over(torch.zeros(20, 3), torch.zeros(20, 3), directions, FACING_CAMERA)
    out.sum().backward()
    grad = layer.texture.grad[0].abs().sum(0)
    # v from +0.05 to -0.2 m at u = 0: rows (0.3 - 0.05) / 0.9 * 16 = 4.4 to 8.9 about columns 7 and 8
    assert torch.isfinite(layer.texture.grad).all() and grad[:, 7:9].sum() > 0 and grad[:, :6].sum() == 0
    assert grad[:3].sum() == 0 and grad[10:].sum() == 0


def test_the_plane_stands_at_the_neck_turned_with_the_root():
    joints = torch.tensor([[0.0, -0.2, -1.0], [0.0, -0.1, -1.0], [0.0, 0.0, -0.9]])
    rotation = torch.eye(3)
    origin, axes = body_frame(joints, rotation, ("root", "neck", "jaw"))
    assert origin.tolist() == joints[1].tolist() and axes is rotation
    origin, _ = body_frame(joints, rotation, ("root", "jaw", "eye"))
    assert origin.tolist() == joints[0].tolist()
