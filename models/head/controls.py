"""Controls: the one description of a head's state used by sliders, datasets and renderers (docs/formats.md)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from models.head.model import HeadModel


class ControlsError(ValueError):
    """Controls that do not fit the format or the head model; the message names the problem."""


def _zeros3() -> np.ndarray:
    return np.zeros(3, np.float32)


@dataclass(frozen=True, eq=False)
class Controls:
    """One head state. Rotations are axis-angle in radians; translation in metres.

    shape, expression: coefficient vectors; shorter than the model's basis means the rest are 0.
    """

    shape: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    expression: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    root: np.ndarray = field(default_factory=_zeros3)
    neck: np.ndarray = field(default_factory=_zeros3)
    jaw: np.ndarray = field(default_factory=_zeros3)
    gaze_left: np.ndarray = field(default_factory=_zeros3)
    gaze_right: np.ndarray = field(default_factory=_zeros3)
    translation: np.ndarray = field(default_factory=_zeros3)

    def rotation(self, joint: str) -> np.ndarray:
        """The axis-angle rotation the controls give a joint of CONTROL_JOINTS."""
        return {"root": self.root, "neck": self.neck, "jaw": self.jaw,
                "eye_l": self.gaze_left, "eye_r": self.gaze_right}[joint]

    def head_rotation(self) -> np.ndarray:
        """(3,) axis-angle: the head's own turn, the root's and the neck's composed (R_root R_neck: the neck hangs
        from the root). A tracked video's frames keep the body's slow turn in the root and the head's own in the
        neck (models/tracking/torso.py); where the neck is still, the root's."""
        from scipy.spatial.transform import Rotation

        if not np.any(self.neck):
            return np.asarray(self.root, np.float32)
        turn = Rotation.from_rotvec(np.asarray(self.root, np.float64)) * Rotation.from_rotvec(
            np.asarray(self.neck, np.float64))
        return turn.as_rotvec().astype(np.float32)

    def with_expression(self, head: HeadModel, weights: dict[str, float]) -> Controls:
        """A copy with named expression weights set (others kept)."""
        expr = fit_length(self.expression, head.num_expression, "expression")
        for name, w in weights.items():
            try:
                expr[head.expression_index(name)] = w
            except KeyError as e:
                raise ControlsError(e.args[0]) from None
        return replace(self, expression=expr)


def fit_length(vec: np.ndarray, n: int, what: str) -> np.ndarray:
    """vec padded with zeros to n entries; an error if it is longer than n."""
    vec = np.asarray(vec, np.float32).ravel()
    if len(vec) > n:
        raise ControlsError(f"{what} has {len(vec)} values but the head model has {n} components")
    out = np.zeros(n, np.float32)
    out[: len(vec)] = vec
    return out


def _vec3(value: object, where: str) -> np.ndarray:
    arr = _numbers(value, where)
    if arr.shape != (3,):
        raise ControlsError(f"{where} must be 3 numbers (axis-angle radians or metres), got {value!r}")
    return arr


LIMITS = {"shape": 10.0, "expression": 10.0, "pose": 2 * np.pi, "gaze": np.pi / 2, "translation": 2.0}
"""The largest magnitude each control takes from a file: identity and expression weights (a model's useful range
is about -2..2; 1e30 overflowed to garbage), rotations (radians), gaze (radians), translation (metres)."""


def _numbers(value: object, where: str) -> np.ndarray:
    if not isinstance(value, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    ):
        raise ControlsError(f"{where} must be a list of numbers, got {value!r}")
    arr = np.asarray(np.asarray(value, np.float64).clip(-1e30, 1e30), np.float32)
    if not np.all(np.isfinite(np.asarray(value, np.float64))):
        raise ControlsError(f"{where} has non-finite numbers")
    limit = LIMITS[where.split(".")[0]]
    if np.abs(arr).max(initial=0.0) > limit:
        raise ControlsError(f"{where} has a value of magnitude {np.abs(arr).max():g}; at most {limit:g} is allowed")
    return arr


_KEYS = {"shape", "expression", "pose", "gaze", "translation"}


def controls_from_dict(data: object, head: HeadModel | None = None) -> Controls:
    """Controls from the JSON form of docs/formats.md; every key optional, missing means neutral.

    A named expression dict needs the head model to map names to indices.
    """
    if not isinstance(data, dict):
        raise ControlsError(f"controls must be a JSON object, got {type(data).__name__}")
    unknown = set(data) - _KEYS
    if unknown:
        raise ControlsError(f"unknown key(s) {sorted(unknown)}; expected some of {sorted(_KEYS)}")
    c = Controls()
    if "shape" in data:
        c = replace(c, shape=_numbers(data["shape"], "shape"))
    expr = data.get("expression")
    if isinstance(expr, dict):
        if head is None:
            raise ControlsError("named expressions need a head model")
        bad = [k for k, v in expr.items() if not isinstance(v, int | float) or isinstance(v, bool)
               or not np.isfinite(v) or abs(v) > LIMITS["expression"]]
        if bad:
            raise ControlsError(f"expression weights must be finite numbers of magnitude at most "
                                f"{LIMITS['expression']:g}: {bad}")
        c = c.with_expression(head, {k: float(v) for k, v in expr.items()})
    elif expr is not None:
        c = replace(c, expression=_numbers(expr, "expression"))
    pose = data.get("pose", {})
    if not isinstance(pose, dict) or set(pose) - {"root", "neck", "jaw"}:
        raise ControlsError(f"pose must be an object with keys root, neck, jaw; got {pose!r}")
    gaze = data.get("gaze", {})
    if not isinstance(gaze, dict) or set(gaze) - {"left", "right"}:
        raise ControlsError(f"gaze must be an object with keys left, right; got {gaze!r}")
    c = replace(
        c,
        **{k: _vec3(v, f"pose.{k}") for k, v in pose.items()},
        **{f"gaze_{k}": _vec3(v, f"gaze.{k}") for k, v in gaze.items()},
    )
    if "translation" in data:
        c = replace(c, translation=_vec3(data["translation"], "translation"))
    if head is not None:
        fit_length(c.shape, head.num_shape, "shape")
        fit_length(c.expression, head.num_expression, "expression")
    return c


def controls_to_dict(c: Controls) -> dict:
    """The JSON form of controls (inverse of controls_from_dict, expressions as a list)."""
    return {
        "shape": c.shape.tolist(),
        "expression": c.expression.tolist(),
        "pose": {"root": c.root.tolist(), "neck": c.neck.tolist(), "jaw": c.jaw.tolist()},
        "gaze": {"left": c.gaze_left.tolist(), "right": c.gaze_right.tolist()},
        "translation": c.translation.tolist(),
    }


def load_controls(path: str | Path, head: HeadModel | None = None) -> Controls:
    """Controls from a JSON file; ControlsError names the file and the problem."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise ControlsError(f"{path}: cannot read controls ({e.strerror})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ControlsError(f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    try:
        return controls_from_dict(data, head)
    except ControlsError as e:
        raise ControlsError(f"{path}: {e}") from None
