"""Controls from files are refused at the boundary when they are not finite or far out of range."""

from __future__ import annotations

import numpy as np
import pytest

from models.head.controls import ControlsError, controls_from_dict
from models.head.sources import load_head


@pytest.mark.parametrize(("data", "where"), [
    ({"expression": [0.5, 1e30]}, "expression"), ({"expression": {"jawOpen": 1e30}}, "jawOpen"),
    ({"expression": {"jawOpen": float("nan")}}, "jawOpen"), ({"translation": [0, 0, 5]}, "translation"),
    ({"pose": {"root": [0, 100, 0]}}, "pose.root"), ({"gaze": {"left": [0, 3, 0]}}, "gaze.left"),
    ({"shape": [float("inf")]}, "shape")])
def test_out_of_range_controls_are_refused(data, where):
    with pytest.raises(ControlsError, match=where):
        controls_from_dict(data, load_head("builtin"))


def test_ordinary_controls_pass():
    c = controls_from_dict({"expression": [0.5, -1.5], "pose": {"jaw": [0.3, 0, 0]}, "translation": [0, 0, -0.5],
                            "gaze": {"left": [0.2, -0.1, 0]}}, load_head("builtin"))
    np.testing.assert_allclose(c.translation, [0, 0, -0.5])
    assert c.expression[1] == -1.5
