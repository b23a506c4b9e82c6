"""The synthetic capture protocol (CoDyNeRF, Section 4): in the first half the camera pans around a nearly
still head while the expression varies; in the second the camera is fixed at head height and the head
turns (yaw to +-45 degrees, pitch +-20) while expressing. Held-out test frames combine expressions and
poses that no training frame has."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from models.head.controls import Controls
from models.head.model import HeadModel

#: Semantic channels the script drives, and the names each head model calls them.
CHANNELS = ("jaw", "smile", "frown", "brow_raise", "brow_down", "blink_l", "blink_r", "pucker")
_NAMES = {
    "smile": (("smile_L", "smile_R"), ("mouthSmile_L", "mouthSmile_R")),
    "frown": (("frown_L", "frown_R"), ("mouthFrown_L", "mouthFrown_R")),
    "brow_raise": (("browRaise_L", "browRaise_R"), ("browInnerUp_L", "browInnerUp_R", "browOuterUp_L",
                                                    "browOuterUp_R")),
    "brow_down": (("browDown_L", "browDown_R"),),
    "blink_l": (("blink_L",), ("eyeBlink_L",)),
    "blink_r": (("blink_R",), ("eyeBlink_R",)),
    "pucker": (("pucker",), ("mouthPucker",)),
    "jaw": ((), ("jawOpen",)),
}
JAW_OPEN_RAD = 0.3


@dataclass(frozen=True)
class Rig:
    """How semantic channels become controls for one head model."""

    directions: dict[str, np.ndarray]  # channel -> expression vector at weight 1
    jaw_joint: bool  # the jaw channel turns the jaw joint (else it is an expression direction)

    def controls(self, weights: dict[str, float], base: Controls) -> Controls:
        expr = sum((w * self.directions[c] for c, w in weights.items() if c in self.directions),
                   np.zeros_like(next(iter(self.directions.values()))))
        jaw = np.array([JAW_OPEN_RAD * weights.get("jaw", 0.0), 0.0, 0.0]) if self.jaw_joint else base.jaw
        return replace(base, expression=expr.astype(np.float32), jaw=jaw.astype(np.float32))


def make_rig(head: HeadModel) -> Rig:
    """Named expressions where the model has them (built-in, ICT); otherwise fixed random directions in
    the first ten components (FLAME's components have no names)."""
    E = head.num_expression
    rng = np.random.default_rng(7)
    dirs: dict[str, np.ndarray] = {}
    for ch in CHANNELS:
        vec = np.zeros(E, np.float32)
        for names in _NAMES[ch]:
            if names and all(n in head.expr_names for n in names):
                for n in names:
                    vec[head.expression_index(n)] = 1.0
                break
        else:
            if ch == "jaw" and "jaw" in head.joint_names:
                continue
            k = min(E, 10)
            vec[:k] = rng.normal(0, 0.8, k)
        dirs[ch] = vec
    return Rig(dirs, jaw_joint="jaw" in head.joint_names)


@dataclass(frozen=True)
class FrameSpec:
    """One frame of the script: expression channel weights, head rotation and camera orbit."""

    weights: dict[str, float]
    head_yaw_deg: float
    head_pitch_deg: float
    camera_yaw_deg: float
    camera_pitch_deg: float

    def control_vector(self) -> np.ndarray:
        """Expression channels and head pose (radians), for telling frames apart."""
        return np.array([self.weights.get(c, 0.0) for c in CHANNELS]
                        + [math.radians(self.head_yaw_deg), math.radians(self.head_pitch_deg)])


def _smooth_pulse(t: np.ndarray, start: float, length: float) -> np.ndarray:
    x = np.clip((t - start) / length, 0, 1)
    return np.sin(np.pi * x) ** 2


def expression_track(n: int, rng: np.random.Generator) -> list[dict[str, float]]:
    """Expressions over n frames: segments of talking, smiling, frowning, brows up and down, one at a time
    (with talking under some), and blinks every 30 to 60 frames."""
    t = np.arange(n, dtype=np.float64)
    w = {c: np.zeros(n) for c in CHANNELS}
    seg = max(8, n // 12)
    order = ["jaw", "smile", "brow_raise", "frown", "jaw", "brow_down", "pucker", "smile"]
    for k, start in enumerate(range(0, n, seg)):
        ch = order[k % len(order)]
        amp = rng.uniform(0.6, 1.0)
        pulse = _smooth_pulse(t, start, seg)
        if ch == "jaw":  # talking: the jaw opens and closes a few times a segment
            w["jaw"] += amp * pulse * 0.5 * (1 - np.cos(2 * np.pi * (t - start) / rng.uniform(5, 8)))
        else:
            w[ch] += amp * pulse
    blink = rng.uniform(10, 30)
    while blink < n - 4:
        pulse = _smooth_pulse(t, blink, 5)
        w["blink_l"] += pulse
        w["blink_r"] += pulse
        blink += rng.uniform(30, 60)
    return [{c: float(np.clip(w[c][i], 0, 1)) for c in CHANNELS if w[c][i] > 1e-3} for i in range(n)]


TURN_DEG = 45.0
"""The protocol's largest head turn (yaw) in its second half; the camera pans to 40 degrees in the first."""


def training_script(n: int, rng: np.random.Generator, turn_deg: float = TURN_DEG) -> list[FrameSpec]:
    """n frames of the capture protocol; turn_deg scales its yaws (the head's turns and the camera's pan) to at
    most that many degrees either way (20: a capture that sees only the front, as a phone's does)."""
    share = turn_deg / TURN_DEG
    expr = expression_track(n, rng)
    half = n // 2
    frames = []
    for i in range(n):
        if i < half:  # camera pans around a nearly still head
            s = i / max(half - 1, 1)
            frames.append(FrameSpec(expr[i], 2.0 * math.sin(5.1 * s), 1.5 * math.sin(3.7 * s),
                                    40.0 * share * math.sin(2 * math.pi * s), 8.0 * math.sin(4 * math.pi * s)))
        else:  # camera fixed at head height, the head turns
            s = (i - half) / max(n - half - 1, 1)
            frames.append(FrameSpec(expr[i], turn_deg * math.sin(2 * math.pi * s),
                                    20.0 * math.sin(6 * math.pi * s + 0.7), 0.0, 0.0))
    return frames


def held_out_script(n: int, train: list[FrameSpec], rng: np.random.Generator, min_distance: float = 0.25,
                    turn_deg: float = TURN_DEG) -> list[FrameSpec]:
    """n frames whose expression-and-pose vectors are at least `min_distance` from every training frame's:
    several expressions at once under head poses off the training path (yaws within 40/45 of turn_deg)."""
    train_vecs = np.stack([f.control_vector() for f in train])
    out = []
    while len(out) < n:
        chans = rng.choice(["smile", "frown", "brow_raise", "brow_down", "pucker"], size=2, replace=False)
        weights = {str(c): float(rng.uniform(0.5, 1.0)) for c in chans}
        weights["jaw"] = float(rng.uniform(0.3, 0.9))
        if rng.uniform() < 0.4:
            weights["blink_l"] = weights["blink_r"] = float(rng.uniform(0.6, 1.0))
        yaw = 40.0 * (turn_deg / TURN_DEG)
        spec = FrameSpec(weights, float(rng.uniform(-yaw, yaw)), float(rng.uniform(-18, 18)), 0.0, 0.0)
        if np.linalg.norm(train_vecs - spec.control_vector(), axis=1).min() >= min_distance:
            out.append(spec)
    return out
