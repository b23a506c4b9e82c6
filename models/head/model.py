"""The one in-memory form of a morphable head model (docs/head-models.md), whatever file it came from."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

#: Names of the joints the controls know about, in FLAME's order.
CONTROL_JOINTS = ("root", "neck", "jaw", "eye_l", "eye_r")


class HeadModelError(ValueError):
    """A head-model file that cannot be read; the message names the file and the problem."""


@dataclass(frozen=True, eq=False)
class Landmarks:
    """Landmarks as points on the surface: vertex ids, or barycentric points on triangles.

    vertex_ids: (L,) int, or None when given as barycentric points.
    faces: (L,) triangle ids, bary: (L,3) barycentric weights (rows sum to 1).
    """

    vertex_ids: np.ndarray | None = None
    faces: np.ndarray | None = None
    bary: np.ndarray | None = None

    @property
    def count(self) -> int:
        if self.vertex_ids is not None:
            return len(self.vertex_ids)
        return 0 if self.faces is None else len(self.faces)

    def as_barycentric(self, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(L,3) vertex ids and (L,3) weights, for either form."""
        if self.vertex_ids is not None:
            ids = np.repeat(self.vertex_ids[:, None], 3, axis=1)
            weights = np.zeros((len(ids), 3), np.float32)
            weights[:, 0] = 1.0
            return ids.astype(np.int64), weights
        if self.faces is None:
            return np.zeros((0, 3), np.int64), np.zeros((0, 3), np.float32)
        return triangles[self.faces].astype(np.int64), self.bary.astype(np.float32)


@dataclass(frozen=True, eq=False)
class HeadModel:
    """A morphable head: template, linear bases, a joint tree with skinning weights, landmarks.

    Metres, +y up, +z out of the face, the subject's left on +x.
    """

    name: str
    template: np.ndarray  # (V,3) float32
    triangles: np.ndarray  # (F,3) int32
    shape_basis: np.ndarray  # (V,3,S)
    expr_basis: np.ndarray  # (V,3,E)
    J_regressor: np.ndarray  # (J,V) dense; rows sum to 1
    weights: np.ndarray  # (V,J); rows sum to 1
    parents: np.ndarray  # (J,) int, parents[0] == -1
    joint_names: tuple[str, ...]
    pose_basis: np.ndarray  # (V,3,(J-1)*9) or (V,3,0)
    landmarks: Landmarks = field(default_factory=Landmarks)
    expr_names: tuple[str, ...] = ()
    uv: np.ndarray | None = None  # (T,2)
    triangles_uv: np.ndarray | None = None  # (F,3)

    def __post_init__(self) -> None:
        check_head_model(self)

    @property
    def num_vertices(self) -> int:
        return self.template.shape[0]

    @cached_property
    def surface_key(self) -> str:
        """A digest of the template's vertices and triangles: the same for the same surface whatever file or name it
        came from, and another for any other (what is computed from the surface alone is cached under it:
        the primitives' layout and chart)."""
        digest = hashlib.blake2b(digest_size=16)
        for a in (self.template, self.triangles):
            a = np.ascontiguousarray(a)
            digest.update(f"{a.dtype.str}{a.shape}".encode())
            digest.update(a.tobytes())
        return digest.hexdigest()

    @property
    def num_shape(self) -> int:
        return self.shape_basis.shape[2]

    @property
    def num_expression(self) -> int:
        return self.expr_basis.shape[2]

    @property
    def num_joints(self) -> int:
        return len(self.parents)

    def expression_index(self, name: str) -> int:
        """Index of a named expression component; KeyError lists a few valid names."""
        if name in self.expr_names:
            return self.expr_names.index(name)
        raise KeyError(
            f"head model '{self.name}' has no expression '{name}'"
            f" (it has {', '.join(self.expr_names[:12])}{', ...' if len(self.expr_names) > 12 else ''})"
        )


def check_head_model(m: HeadModel) -> None:
    """Raise HeadModelError naming the first field whose shape or values are inconsistent."""

    def fail(msg: str) -> None:
        raise HeadModelError(f"head model '{m.name}': {msg}")

    if m.template.ndim != 2 or m.template.shape[1] != 3:
        fail(f"template must be (V,3), got {m.template.shape}")
    V = m.template.shape[0]
    J = len(m.parents)
    if m.triangles.ndim != 2 or m.triangles.shape[1] != 3:
        fail(f"triangles must be (F,3), got {m.triangles.shape}")
    if m.triangles.size and (m.triangles.min() < 0 or m.triangles.max() >= V):
        fail(f"triangles index vertices outside [0, {V})")
    for name, basis in (("shape_basis", m.shape_basis), ("expr_basis", m.expr_basis)):
        if basis.ndim != 3 or basis.shape[:2] != (V, 3):
            fail(f"{name} must be (V,3,K) with V={V}, got {basis.shape}")
    if m.J_regressor.shape != (J, V):
        fail(f"J_regressor must be (J,V)=({J},{V}), got {m.J_regressor.shape}")
    if m.weights.shape != (V, J):
        fail(f"weights must be (V,J)=({V},{J}), got {m.weights.shape}")
    if J < 1 or m.parents[0] != -1 or any(not 0 <= p < j for j, p in enumerate(m.parents[1:], 1)):
        fail(f"parents must start with -1 and point to earlier joints, got {m.parents.tolist()}")
    if len(m.joint_names) != J:
        fail(f"{len(m.joint_names)} joint names for {J} joints")
    if m.pose_basis.shape not in ((V, 3, (J - 1) * 9), (V, 3, 0)):
        fail(f"pose_basis must be (V,3,{(J - 1) * 9}) or empty, got {m.pose_basis.shape}")
    if m.expr_names and len(m.expr_names) != m.expr_basis.shape[2]:
        fail(f"{len(m.expr_names)} expression names for {m.expr_basis.shape[2]} components")
    for name in ("template", "shape_basis", "expr_basis", "weights", "J_regressor", "pose_basis"):
        if not np.all(np.isfinite(getattr(m, name))):
            fail(f"{name} has non-finite values")
    lm = m.landmarks
    if lm.vertex_ids is not None and lm.vertex_ids.size and (
        lm.vertex_ids.min() < 0 or lm.vertex_ids.max() >= V
    ):
        fail("landmark vertex ids out of range")
    if lm.faces is not None and (lm.faces.min() < 0 or lm.faces.max() >= len(m.triangles)):
        fail("landmark faces out of range")


def portrait_vertices(head: HeadModel, vertices: np.ndarray | None = None) -> np.ndarray:
    """The vertices a portrait frames: the head down to 8 cm below its lowest landmark (the chin), so a
    long neck or shoulders do not shrink the face. Chosen on the neutral template, so poses compare."""
    v = head.template if vertices is None else vertices
    ids, bary = head.landmarks.as_barycentric(head.triangles)
    if len(ids) == 0:
        return v
    lowest = float((head.template[ids] * bary[..., None]).sum(1)[:, 1].min())
    keep = head.template[:, 1] >= lowest - 0.08
    return v[keep] if keep.sum() >= 3 else v
