"""What an avatar folder says of its avatar beside the weights (models/avatars/card.py), read alone as the studio's
window reads it: the same as the loaded avatar's, without building a network or reading a weight."""

from __future__ import annotations

import numpy as np
import pytest

import models.avatars.registry as registry
from models.avatars.base import Avatar
from models.avatars.registry import load_avatar, read_card
from models.head.controls import Controls
from tests.conftest import CODYNERF_DEMO, DEMO


@pytest.mark.parametrize("folder", [DEMO, CODYNERF_DEMO], ids=["primitives", "codynerf"])
def test_the_card_read_alone_is_the_loaded_avatars(folder, monkeypatch):
    avatar, meta = load_avatar(folder)
    loaded = avatar.card

    def refuse(*args, **kwargs):
        raise AssertionError("the card is read without the avatar's weights or network")

    monkeypatch.setattr(Avatar, "__init__", refuse)
    monkeypatch.setattr(registry, "load_checkpoint", refuse)
    card = read_card(folder)
    assert card.name == loaded.name == meta["model"] and card.effects == avatar.effects
    assert card.default_buffers() == avatar.default_buffers()
    assert card.inspection_buffers() == avatar.inspection_buffers()
    assert card.presets == loaded.presets and card.presets_measured == loaded.presets_measured
    assert card.capture_px == loaded.capture_px == (meta["image_px"][0] if "image_px" in meta else None)
    assert card.view_range == loaded.view_range
    np.testing.assert_array_equal(card.rest_translation, loaded.rest_translation)
    np.testing.assert_array_equal(card.rest_vertices(), avatar.head_model.template + card.rest_translation)
    t = np.asarray(meta.get("rest_pose", {}).get("translation", [0.0, 0.0, 0.0]), np.float32)
    np.testing.assert_allclose(card.at_rest(Controls(translation=np.ones(3, np.float32))).translation, t + 1.0)


def test_an_older_avatar_json_leaves_the_card_unrecorded(tmp_path):
    """Fields an older avatar.json lacks or holds malformed: no rest pose (the origin), views unknown, no size."""
    import json
    import shutil

    shutil.copytree(DEMO, tmp_path / "av")
    path = tmp_path / "av" / "avatar.json"
    meta = json.loads(path.read_text())
    meta.pop("view_range")
    meta["rest_pose"] = {"translation": [0.0, "x", 1.0]}
    meta["image_px"] = [8, 8]
    path.write_text(json.dumps(meta))
    card = read_card(tmp_path / "av")
    assert card.view_range is None and card.capture_px is None and card.turntable_sweep_deg() == 0.0
    np.testing.assert_array_equal(card.rest_translation, np.zeros(3))
    assert not card.views_beyond(180.0)


def test_the_cards_turntable_camera_circles_the_head_where_the_capture_held_it():
    """The camera every turntable, sheet and bench uses (AvatarCard.turntable_camera): about the rest head's centre
    (its translation counted), 5 degrees above it, at the yaw asked (0: in front, on +z; 90: on +x), the head
    inside the square frame; a zoom of 2 halves the distance beyond the head's cylinder."""
    card = read_card(DEMO)
    v = card.rest_vertices()
    centre = 0.5 * (v.min(0) + v.max(0))
    for yaw in (0.0, 90.0, 180.0):
        cam = card.turntable_camera(yaw, 64)
        assert (cam.width_px, cam.height_px) == (64, 64)
        d = cam.position - centre
        flat = float(np.hypot(d[0], d[2]))
        assert np.degrees(np.arctan2(d[1], flat)) == pytest.approx(5.0, abs=1e-6)
        np.testing.assert_allclose(d[[0, 2]] / flat, [np.sin(np.radians(yaw)), np.cos(np.radians(yaw))], atol=1e-9)
        p = np.c_[v, np.ones(len(v))] @ (cam.projection @ cam.view).T
        assert np.abs(p[:, :2] / p[:, 3:]).max() <= 1.0
    radius = float(np.linalg.norm((v - centre)[:, [0, 2]], axis=1).max())
    far, near = (float(np.linalg.norm(card.turntable_camera(0.0, 64, zoom=z).position - centre)) for z in (1, 2))
    assert near - radius == pytest.approx((far - radius) / 2, rel=1e-3)
