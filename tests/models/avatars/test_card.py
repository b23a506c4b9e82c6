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
