"""New views of an avatar held to the views its capture saw (models/avatars/components/views.py): a tracked
video's fixed camera gives every colour network the direction to that camera; a model that reads one view a
frame (the primitives' decoder) is held to the cone of its training frames' views."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from models.avatars.components.views import into_cone, view_cone
from models.avatars.registry import load_avatar
from models.avatars.rendering import render_image
from models.head.controls import Controls
from render.camera import turntable_camera
from render.gl.raster import Rasterizer
from tests.conftest import BUILTIN_AVATAR as DEMO  # its capture's views are the numbers below
from tests.conftest import CODYNERF_DEMO


def unit(deg_from_z: float, azimuth_deg: float = 0.0) -> list[float]:
    t, a = math.radians(deg_from_z), math.radians(azimuth_deg)
    return [math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t)]


def angle_deg(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.rad2deg(torch.acos((a * b).sum(-1).clamp(-1, 1)))


def test_cone_holds_every_direction_and_moves_others_to_its_rim():
    """Directions 0-10 degrees from z at several azimuths: a cone about z of 10 + 2 degrees. A direction inside
    is untouched; one 40 degrees out at azimuth 30 lands 12 degrees from the axis at the same azimuth; the
    opposite of the axis and the zero vector land on the rim, finite."""
    dirs = torch.tensor([unit(t, a) for t in (0, 5, 10) for a in (0, 120, 240)])
    axis, cos = view_cone(dirs)
    assert angle_deg(axis, torch.tensor([0.0, 0.0, 1.0])) < 1e-3
    assert math.degrees(math.acos(cos)) == pytest.approx(12.0, abs=1e-4)
    v = torch.tensor([unit(7, 50), unit(40, 30), [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]])
    out = into_cone(v, axis, cos)
    assert torch.equal(out[0], v[0])
    np.testing.assert_allclose(out[1].numpy(), unit(12, 30), atol=1e-5)
    assert torch.isfinite(out).all()
    np.testing.assert_allclose(angle_deg(out[2:], axis).numpy(), [12.0, 12.0], atol=1e-3)
    np.testing.assert_allclose(out.norm(dim=-1).numpy(), 1.0, atol=1e-6)


def test_views_from_all_round_or_a_hemisphere_give_no_cone():
    ring = torch.tensor([unit(90, a) for a in range(0, 360, 30)])  # a ring of cameras about the head
    assert view_cone(ring) is None
    # Mostly from the front, three from behind the side: 95 + 2 degrees from the axis, wider than a hemisphere.
    assert view_cone(torch.tensor([unit(0)] + [unit(95, a) for a in (0, 120, 240)])) is None
    assert view_cone(torch.full((3, 3), float("nan"))) is None


@pytest.mark.gl
def test_a_fixed_camera_gives_the_colour_the_way_to_it(gl):
    """CoDyNeRF on a capture whose camera stood still: set to the rendering camera's own position, nothing changes
    (the view is the ray reversed, as before); set elsewhere, the colours change and the opacity does not (the
    density reads no view). A capture whose camera moved records no position."""
    avatar, _ = load_avatar(CODYNERF_DEMO)
    r = Rasterizer(gl)
    controls = avatar.card.at_rest(Controls())
    cam = turntable_camera(avatar.card.rest_vertices(), 25.0, 5.0, width_px=32, height_px=32)
    plain = render_image(avatar, cam, controls, rasterizer=r)
    eye = torch.as_tensor(cam.position, dtype=torch.float32)
    avatar.note_views(SimpleNamespace(origins=eye.expand(4, 3)))
    assert torch.equal(avatar.views.eye, eye)
    same = render_image(avatar, cam, controls, rasterizer=r)
    np.testing.assert_allclose(same["rgb"], plain["rgb"], atol=2e-5)
    front = turntable_camera(avatar.card.rest_vertices(), 0.0, 5.0, width_px=32, height_px=32)
    avatar.note_views(SimpleNamespace(origins=torch.as_tensor(front.position, dtype=torch.float32).expand(4, 3)))
    held = render_image(avatar, cam, controls, rasterizer=r)
    np.testing.assert_allclose(held["opacity"], plain["opacity"], atol=1e-6)
    shown = plain["opacity"] > 0.5
    assert np.abs(held["rgb"] - plain["rgb"])[shown].max() > 1e-3
    moving = load_avatar(CODYNERF_DEMO)[0]
    moving.note_views(SimpleNamespace(origins=torch.tensor([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0]])))
    assert moving.views.towards_camera(torch.zeros(1, 3)) is None


@pytest.mark.gl
def test_primitives_decode_new_views_as_the_nearest_seen(gl):
    """The primitives' decoder reads one view a frame: trained on frames with the head turned -10..10 degrees
    before one camera, a camera 40 degrees round decodes what a camera on the cone's rim (12 degrees) decodes."""
    avatar, _ = load_avatar(DEMO)
    r = Rasterizer(gl)
    geo = avatar.frame_geometry(avatar.card.at_rest(Controls()), r)
    eye = geo.translation + torch.tensor([0.0, 0.0, 1.0])  # in front of the head, on its forward axis
    geos = [avatar.frame_geometry(avatar.card.at_rest(Controls(root=np.array([0.0, math.radians(y), 0.0],
                                                                          np.float32))), r) for y in (-10, 0, 10)]
    avatar.note_views(SimpleNamespace(origins=eye.expand(3, 3), geometry=geos))
    # 10 degrees each side and the margin (the root turns about the head's centre, not its origin: a little more)
    assert math.degrees(math.acos(float(avatar.views.cos))) == pytest.approx(12.0, abs=0.1)
    code = avatar.codes(None)

    def colour(at: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            return avatar.decode(geo, code, at)[0].colour

    turned = torch.as_tensor(Rotation.from_euler("y", 40.0, degrees=True).apply((eye - geo.translation).numpy()),
                             dtype=torch.float32) + geo.translation
    rim = into_cone(avatar.view_of(geo, turned)[None], avatar.views.axis, float(avatar.views.cos))[0]
    assert float(angle_deg(rim, avatar.views.axis)) == pytest.approx(math.degrees(math.acos(float(avatar.views.cos))),
                                                                    abs=1e-3)
    on_rim = geo.translation + geo.rotation @ rim  # a camera 1 m away in that direction (head frame -> world)
    assert torch.allclose(colour(turned), colour(on_rim), atol=1e-5)
    inside = torch.as_tensor(Rotation.from_euler("y", 5.0, degrees=True).apply((eye - geo.translation).numpy()),
                             dtype=torch.float32) + geo.translation
    assert not torch.allclose(colour(inside), colour(on_rim), atol=1e-5)
