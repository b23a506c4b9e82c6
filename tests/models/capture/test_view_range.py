"""The directions a capture saw the head from, in the head's frame; what the avatar says of views beyond."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from models.avatars.registry import load_avatar
from models.capture.dataset import CaptureSplit, Frame
from models.capture.frames import view_range
from models.head.controls import Controls
from tests.conftest import DEMO


def split_of(frames: list[Frame]) -> CaptureSplit:
    return CaptureSplit(Path("."), "train", "avatar-studio", 8, 8, (8.0, 8.0, 4.0, 4.0), "builtin", np.zeros(0),
                        np.zeros(3), None, frames)


def frame(k: int, camera_at: tuple[float, float, float], root_yaw_deg: float) -> Frame:
    c2w = np.eye(4)
    c2w[:3, 3] = camera_at
    controls = Controls(root=np.array([0.0, np.radians(root_yaw_deg), 0.0], np.float32))
    return Frame(k, Path(f"{k}.png"), c2w, np.zeros(0), controls)


def test_view_range_hand_worked():
    """A camera 1 m in front: the head turned 20 degrees to its left (+y) sees the camera 20 degrees to its right
    (yaw -20); turned 15 to its right, at +15. A camera 1 m up and 1 m in front: pitch 45."""
    frames = [frame(0, (0, 0, 1), 20.0), frame(1, (0, 0, 1), -15.0), frame(2, (0, 1, 1), 0.0)]
    r = view_range(split_of(frames), np.zeros(3))
    assert r["yaw_deg"] == pytest.approx([-20.0, 15.0], abs=0.05)
    assert r["pitch_deg"] == pytest.approx([0.0, 45.0], abs=0.05)


def test_the_avatar_knows_which_views_it_saw():
    avatar, _ = load_avatar(DEMO)
    assert avatar.card.view_range is not None and avatar.card.views_beyond(180.0)  # its capture saw its front
    avatar.card = replace(avatar.card, view_range=None)  # an older avatar: its views unknown
    assert not avatar.card.views_beyond(150.0) and avatar.card.turntable_sweep_deg() in (0.0, pytest.approx(0.0))
    avatar.card = replace(avatar.card, view_range={"yaw_deg": [-20.0, 15.0], "pitch_deg": [-5.0, 5.0]})
    assert avatar.card.turntable_sweep_deg() == 30.0  # the farther side, 20, and 10 more
    assert not avatar.card.views_beyond(24.0) and avatar.card.views_beyond(26.0) and avatar.card.views_beyond(-31.0)
    assert avatar.card.views_beyond(180.0) and not avatar.card.views_beyond(360.0 + 5.0)
