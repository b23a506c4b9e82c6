"""A head model's joints as a glTF skin: pure functions of its arrays.

glTF skins a vertex as v' = sum_j w_j G_j IBM_j v (glTF 2.0, "Skins"), with G_j the joint node's world transform
and IBM_j its inverse bind matrix. The head model's skinning (models/head/lbs.py) poses joint j by
G_j = G_parent(j) [R_j | J_j - J_parent(j)] about the rest joints J = J_regressor T, so the joint nodes take the
local translations J_j - J_parent(j) (the root's own J_0), and IBM_j = translate(-J_j): at rest G_j IBM_j = I.
What glTF cannot carry: joints that move with the expressions (lbs regresses them from the expressed mesh; glTF's
stay at the template's) and pose correctives (FLAME's pose_basis).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

INFLUENCES = 4
"""Joints a vertex is skinned by in glTF's JOINTS_0/WEIGHTS_0."""


def rest_joints(J_regressor: np.ndarray, template: np.ndarray) -> np.ndarray:
    """(J,3) the joints at rest: J = J_regressor T (J_regressor (J,V), template (V,3)), metres."""
    return (np.asarray(J_regressor, np.float64) @ np.asarray(template, np.float64)).astype(np.float32)


def local_translations(joints: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(J,3) each joint's offset from its parent (the root's from the origin): the joint nodes' translations.

    >>> local_translations(np.array([[0.0, 1, 0], [0, 1.5, 0], [0.5, 1.5, 0]]), np.array([-1, 0, 1])).tolist()
    [[0.0, 1.0, 0.0], [0.0, 0.5, 0.0], [0.5, 0.0, 0.0]]
    """
    out = np.array(joints, np.float32)
    out[1:] -= joints[parents[1:]]
    return out


def inverse_bind_matrices(joints: np.ndarray) -> np.ndarray:
    """(J,4,4) IBM_j = translate(-J_j), row-major (glTF stores them column-major: write the transposes)."""
    m = np.tile(np.eye(4, dtype=np.float32), (len(joints), 1, 1))
    m[:, :3, 3] = -np.asarray(joints, np.float32)
    return m


def strongest_influences(weights: np.ndarray, k: int = INFLUENCES) -> tuple[np.ndarray, np.ndarray]:
    """The k largest skinning weights of each vertex, renormalised to sum to 1, and their joints: (V,k) int, (V,k)
    float32, strongest first; a weight of 0 names joint 0 (glTF's validator asks that no joint repeat with weight).
    weights: (V,J), rows summing to 1.

    >>> j, w = strongest_influences(np.array([[0.1, 0.5, 0.2, 0.1, 0.1], [0.0, 0.0, 1.0, 0.0, 0.0]]), 2)
    >>> j.tolist(), w.astype(float).round(6).tolist()  # 0.5 and 0.2 of 0.7; a rigid vertex: one joint
    ([[1, 2], [2, 0]], [[0.714286, 0.285714], [1.0, 0.0]])
    """
    w = np.asarray(weights, np.float64)
    if w.shape[1] < k:
        w = np.pad(w, ((0, 0), (0, k - w.shape[1])))
    order = np.argsort(-w, axis=1, kind="stable")[:, :k]
    top = np.take_along_axis(w, order, 1)
    top /= np.maximum(top.sum(1, keepdims=True), 1e-12)
    order = np.where(top > 0, order, 0)
    return order.astype(np.int64), top.astype(np.float32)


def quaternions(axis_angle: np.ndarray) -> np.ndarray:
    """(N,4) unit quaternions (x, y, z, w: glTF's order) of N axis-angle rotations (N,3), radians, in time order,
    each on the side of the one before it (q and -q are the same rotation; a sampler interpolating between them
    would take the long way round).

    >>> quaternions(np.array([[0.0, 0, np.pi / 2]])).astype(float).round(6).tolist()  # 90 degrees about +z
    [[0.0, 0.0, 0.707107, 0.707107]]
    """
    q = Rotation.from_rotvec(np.asarray(axis_angle, np.float64).reshape(-1, 3)).as_quat()
    for i in range(1, len(q)):
        if q[i] @ q[i - 1] < 0:
            q[i] = -q[i]
    return q.astype(np.float32)
