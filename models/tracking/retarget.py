"""A driver's tracked controls carried onto an avatar's channels, relative to the driver's neutral frame.

What the driver does is taken relative to their own neutral frame, so that their resting face, whatever it is,
becomes the avatar's rest: expressions and jaw as differences, head rotation as the rotation from the neutral
frame (in the camera's axes), gaze as the change of the eyes' direction. Head translation is not carried: the
avatar stays where its camera frames it.

Across head models (a FLAME-tracked driver onto an ICT or built-in avatar) expressions are carried by name: the
names both models have; FLAME's expression components have no names, so from or onto FLAME only the jaw, gaze and
head rotation are carried, and the note says so.

Channels are named as the animation format names them (`expression.NAME`, `jaw.open`, `head.yaw`, `gaze.yaw`...;
degrees for angles). `reenact` (a whole performance at once) and live driving (one frame as it comes) both go
through `frame_channels`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from models.head.controls import Controls
from models.head.model import HeadModel

Limits = Mapping[str, tuple[float, float]]
"""Where carried values are clipped: "expression" (weights), "jaw.open" and "gaze" (degrees); a missing key is not
clipped."""


@dataclass
class Retarget:
    """How the driver's channels reach the avatar."""

    neutral: int
    carried: list[str] = field(default_factory=list)
    """The avatar's expressions that are driven."""
    missing: list[str] = field(default_factory=list)
    """The driver's expressions the avatar has no counterpart for."""
    note: str = ""


def expression_map(driver: HeadModel, avatar: HeadModel) -> tuple[dict[int, int], list[str], str]:
    """Driver expression index -> avatar expression index: every index for the same model, by name across
    models; the driver's names left over; a note where nothing can be carried."""
    if driver is avatar or (driver.name == avatar.name and driver.num_expression == avatar.num_expression
                            and driver.expr_names == avatar.expr_names):
        return {i: i for i in range(driver.num_expression)}, [], ""
    if not driver.expr_names or not avatar.expr_names:
        which = driver.name if not driver.expr_names else avatar.name
        return {}, [], (f"expressions not carried: head model '{which}' has unnamed expression components (as "
                        "FLAME's), which match no other model's; jaw, gaze and head rotation are carried")
    mapping = {i: avatar.expr_names.index(n) for i, n in enumerate(driver.expr_names) if n in avatar.expr_names}
    missing = [n for n in driver.expr_names if n not in avatar.expr_names]
    note = "" if mapping else (f"no expression names in common between '{driver.name}' and '{avatar.name}'; jaw, "
                               "gaze and head rotation are carried")
    return mapping, missing, note


def calmest_frame(controls: list[Controls]) -> int:
    """The frame with the least expression and jaw: the driver's neutral unless one is named."""
    activity = [float(np.abs(c.expression).sum() + 10.0 * abs(float(c.jaw[0]))) for c in controls]
    return int(np.argmin(activity))


@dataclass(frozen=True)
class Carry:
    """What a driver's frame carries onto an avatar, fixed once for a performance: the neutral frame's controls
    (and its rotations, inverted once), the expression map, the avatar's channel names and joints."""

    rest: Controls
    mapping: dict[int, int]
    names: tuple[str, ...]
    """The avatar's expression channel names (its expression names, else indices)."""
    jaw: bool
    eyes: bool
    head_rest_inv: Rotation
    eyes_rest_inv: tuple[Rotation, Rotation]

    @staticmethod
    def of(rest: Controls, driver: HeadModel, avatar: HeadModel) -> Carry:
        mapping, _, _ = expression_map(driver, avatar)
        names = tuple(avatar.expr_names[j] if j < len(avatar.expr_names) else str(j)
                      for j in range(avatar.num_expression))
        rot = lambda v: Rotation.from_rotvec(np.asarray(v, np.float64)).inv()
        return Carry(rest, mapping, names, "jaw" in avatar.joint_names, {"eye_l", "eye_r"} <= set(avatar.joint_names),
                     rot(rest.head_rotation()), (rot(rest.gaze_left), rot(rest.gaze_right)))


def frame_channels(c: Controls, carry: Carry, limits: Limits) -> dict[str, float]:
    """One driver frame's controls as the avatar's channel values, relative to the neutral frame (carry.rest).

    expression.NAME = w - w_rest; jaw.open = degrees(jaw_x - jaw_x_rest); head.yaw|pitch|roll = the YXZ Euler
    angles (degrees) of R_head R_head_rest^-1 (R_head: the root's and the neck's turns composed, head_rotation; the
    turn since the neutral frame in the camera's axes, which are the avatar's world axes seen from the front);
    gaze.yaw|pitch = the mean over both eyes of the same for the eyes."""
    lo_hi = lambda key: limits.get(key, (-np.inf, np.inf))
    rest = carry.rest
    out: dict[str, float] = {}
    for i, j in carry.mapping.items():
        out[f"expression.{carry.names[j]}"] = float(np.clip(c.expression[i] - rest.expression[i],
                                                            *lo_hi("expression")))
    if carry.jaw:
        out["jaw.open"] = float(np.clip(np.degrees(float(c.jaw[0]) - float(rest.jaw[0])), *lo_hi("jaw.open")))
    yaw, pitch, roll = (Rotation.from_rotvec(c.head_rotation().astype(np.float64)) * carry.head_rest_inv).as_euler(
        "YXZ", degrees=True)
    out["head.yaw"], out["head.pitch"], out["head.roll"] = float(yaw), float(pitch), float(roll)
    if carry.eyes:
        turns = [(Rotation.from_rotvec(np.asarray(g, np.float64)) * e).as_euler("YXZ", degrees=True)
                 for g, e in zip((c.gaze_left, c.gaze_right), carry.eyes_rest_inv, strict=True)]
        gaze = np.clip(np.mean(turns, axis=0), *lo_hi("gaze"))
        out["gaze.yaw"], out["gaze.pitch"] = float(gaze[0]), float(gaze[1])
    return out


def retarget_frames(controls: list[Controls], driver: HeadModel, avatar: HeadModel, neutral: int,
                    limits: Limits) -> tuple[list[dict[str, float]], Retarget]:
    """Every frame's channels (frame_channels) relative to frame `neutral`, and how they were carried."""
    mapping, missing, note = expression_map(driver, avatar)
    carry = Carry.of(controls[neutral], driver, avatar)
    carried = [carry.names[j] for j in sorted(set(mapping.values()))]
    return [frame_channels(c, carry, limits) for c in controls], Retarget(neutral, carried, missing, note)
