"""The body stays where the head turns: a tracked frame's head pose split into the torso's slow turn (the root) and
the head's own (the neck), every vertex of the head where the fit put it.

The fit (fit.py) finds one rigid pose a frame from the face's landmarks and gives it to the root, so the shoulders
and collar of the head model turned with every glance: in a video they do not, and an avatar's primitives on them
were taught a collar that swings with the head (held-out frames of a child looking around showed the top's edge
off where she turned). Where the head model has a neck joint (the built-in head, FLAME), each frame's root becomes
the torso's turn, its rotation smoothed over TORSO_SIGMA_S of the video (a turning body, a camera moving round, still
followed), the neck the rest of the head's turn, and the translation the offset that keeps the neck's pivot, and so
the face, exactly where it was: the root's rotation R about the root joint r, the neck's N about the neck joint n,
send a head vertex x to R (N (x - n) + n - r) + r + t; with R' N' = R N, t' = t + (R - R') (n - r) sends it to the
same place (FLAME's pose-corrective shapes, which follow the neck's turn, move it by their own small amount; the
built-in head has none). Every frame of the video is treated alike (training, validation and held-out)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from models.head.controls import Controls, fit_length
from models.head.model import HeadModel

TORSO_SIGMA_S = 1.5
"""The torso's turn: the head's, smoothed by a Gaussian of this many seconds (a glance is the neck's; a body or a
camera turning over seconds, the root's)."""


def joint_arm(model: HeadModel, a: str, b: str) -> Callable[[Controls], np.ndarray]:
    """The rest vector from joint a to joint b (3,) of a frame's shaped and expressive mesh before any turn (lbs's
    step 2), as a function of its controls: the joint regressor applied to the bases once, not to every frame's
    mesh."""
    rows = model.J_regressor[model.joint_names.index(b)] - model.J_regressor[model.joint_names.index(a)]  # (V,)
    base = rows @ model.template
    by_shape = np.einsum("v,vcs->cs", rows, model.shape_basis)
    by_expression = np.einsum("v,vce->ce", rows, model.expr_basis)
    return lambda c: base + by_shape @ fit_length(c.shape, model.num_shape, "shape") \
        + by_expression @ fit_length(c.expression, model.num_expression, "expression")


def torso_still(controls: list[Controls], model: HeadModel, fps: float, sigma_s: float = TORSO_SIGMA_S
                ) -> list[Controls]:
    """The frames' controls with the torso's slow turn in the root and the head's own in the neck (module
    docstring); unchanged where the head model has no neck joint, or for a single frame."""
    if "neck" not in model.joint_names or len(controls) < 2:
        return controls
    arm_of = joint_arm(model, "root", "neck")
    head = Rotation.from_rotvec(np.stack([c.head_rotation() for c in controls]).astype(np.float64))
    q = head.as_quat()
    q[np.sum(q * q[0], axis=1) < 0] *= -1.0  # one hemisphere, so that the average of nearby turns is a turn
    q = gaussian_filter1d(q, sigma=max(sigma_s * fps, 1e-3), axis=0, mode="nearest")
    torso = Rotation.from_quat(q / np.linalg.norm(q, axis=1, keepdims=True))
    out = []
    for k, c in enumerate(controls):
        arm = arm_of(c)
        before = Rotation.from_rotvec(np.asarray(c.root, np.float64))
        shift = before.apply(arm) - torso[k].apply(arm)
        out.append(replace(c, root=torso[k].as_rotvec().astype(np.float32),
                           neck=(torso[k].inv() * head[k]).as_rotvec().astype(np.float32),
                           translation=(np.asarray(c.translation, np.float64) + shift).astype(np.float32)))
    return out
