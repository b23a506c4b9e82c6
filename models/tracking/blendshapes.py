"""MediaPipe's 52 ARKit-named blendshape scores as a starting point for a head model's expression, jaw and
gaze.

ICT-FaceKit's expressions are ARKit's, named with _L/_R for Left/Right (eyeBlink_L = eyeBlinkLeft; both
name the subject's own side). The built-in head's few expressions map onto the closest ARKit shapes. FLAME's
expressions are PCA components with no names: they start at zero and come from the landmarks alone.
"""

from __future__ import annotations

import numpy as np

from models.head.model import HeadModel

BUILTIN = {  # built-in expression -> ARKit shapes averaged
    "smile_L": ("mouthSmileLeft",), "smile_R": ("mouthSmileRight",),
    "frown_L": ("mouthFrownLeft",), "frown_R": ("mouthFrownRight",),
    "browRaise_L": ("browOuterUpLeft", "browInnerUp"), "browRaise_R": ("browOuterUpRight", "browInnerUp"),
    "browDown_L": ("browDownLeft",), "browDown_R": ("browDownRight",),
    "blink_L": ("eyeBlinkLeft",), "blink_R": ("eyeBlinkRight",),
    "eyeWide_L": ("eyeWideLeft",), "eyeWide_R": ("eyeWideRight",),
    "pucker": ("mouthPucker",), "cheekPuff": ("cheekPuff",),
    "noseSneer": ("noseSneerLeft", "noseSneerRight"), "mouthStretch": ("mouthStretchLeft", "mouthStretchRight"),
}

JAW_OPEN_RAD = 0.35
"""Jaw rotation (about +x, chin down) at a jawOpen score of 1."""
GAZE_YAW_RAD, GAZE_PITCH_RAD = 0.5, 0.35
"""Eye rotation at a full eyeLookOut/In (yaw) and eyeLookUp/Down (pitch) score."""


def arkit_names(name: str) -> tuple[str, ...]:
    """The ARKit shape(s) an ICT-style expression name stands for: eyeBlink_L -> eyeBlinkLeft; ICT's one-sided
    cheekPuff_L/R and browInnerUp_L/R take ARKit's single cheekPuff and browInnerUp."""
    if name.endswith(("_L", "_R")):
        base, side = name[:-2], "Left" if name.endswith("_L") else "Right"
        return (base + side, base)
    return (name,)


def expression_from_scores(model: HeadModel, scores: dict[str, float]) -> np.ndarray:
    """(E,) starting expression weights for the model from one frame's blendshape scores."""
    out = np.zeros(model.num_expression, np.float32)
    if model.name == "builtin":
        for i, name in enumerate(model.expr_names):
            shapes = BUILTIN.get(name, ())
            if shapes:
                out[i] = float(np.mean([scores.get(s, 0.0) for s in shapes]))
        return out
    for i, name in enumerate(model.expr_names):
        for candidate in arkit_names(name):
            if candidate in scores:
                out[i] = scores[candidate]
                break
    return out


def jaw_from_scores(scores: dict[str, float]) -> np.ndarray:
    return np.array([JAW_OPEN_RAD * scores.get("jawOpen", 0.0), 0.0, 0.0], np.float32)


def gaze_from_scores(scores: dict[str, float]) -> np.ndarray:
    """(2,3) left- and right-eye rotations. +y rotation turns the gaze to the subject's left (+x), -x up."""
    s = lambda k: scores.get(k, 0.0)
    left = [-(s("eyeLookUpLeft") - s("eyeLookDownLeft")) * GAZE_PITCH_RAD,
            (s("eyeLookOutLeft") - s("eyeLookInLeft")) * GAZE_YAW_RAD, 0.0]
    right = [-(s("eyeLookUpRight") - s("eyeLookDownRight")) * GAZE_PITCH_RAD,
             (s("eyeLookInRight") - s("eyeLookOutRight")) * GAZE_YAW_RAD, 0.0]
    return np.array([left, right], np.float32)
