"""A synthetic person: the head model's mesh dressed with hair, teeth and lashes for a Look, as one mesh with a
material for every vertex, posed every frame with the head."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.capture.accessories import (
    EYE,
    FaceFrame,
    Part,
    face_frame,
    join_parts,
    lash_parts,
    mouth_interior,
    pose_part,
    teeth_parts,
)
from models.capture.hair import hair_part
from models.capture.looks import Look
from models.capture.scenes import eye_attribute, landmarks68
from models.head.model import HeadModel


@dataclass(frozen=True)
class Person:
    """The head's extra geometry and the material attribute of head and extras together."""

    num_head_vertices: int
    triangles: np.ndarray  # (F,3) the head's triangles, then the extras' (renumbered after the head's vertices)
    canonical: np.ndarray  # (V+N,3) metres
    material: np.ndarray  # (V+N,4) see render.gl.capture.CaptureMesh
    extras: Part | None  # hair, teeth, lashes; None for a head without landmarks
    frame: FaceFrame | None

    def pose(self, canonical_head: np.ndarray, posed_head: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(V+N,3) the posed head's vertices, then its extras' on it; (V+N,3) the strands' directions (0 off the
        hair)."""
        head_tangent = np.zeros_like(posed_head)
        if self.extras is None:
            return posed_head, head_tangent
        verts, tangent = pose_part(self.extras, self.frame, canonical_head, posed_head)
        return np.concatenate([posed_head, verts]), np.concatenate([head_tangent, tangent])


def dress(head: HeadModel, canonical: np.ndarray, look: Look) -> Person:
    """The person a Look makes of a head (canonical: (V,3) the neutral head with its identity)."""
    material = eye_attribute(head, canonical)
    lm = landmarks68(head, canonical)
    if lm is None:  # nothing to place hair and teeth by: the head alone
        return Person(len(canonical), head.triangles, canonical, material, None, None)
    skin = np.flatnonzero(material[:, 3] != EYE)
    frame = face_frame(canonical, lm, skin)
    material[:, 0] = np.where(material[:, 3] != EYE, mouth_interior(canonical, head.triangles, frame),
                              material[:, 0])
    parts = teeth_parts(frame) + lash_parts(frame, canonical, skin)
    if look.hair != "none":
        parts.append(hair_part(look.hair, frame, canonical[skin]))
    extras = join_parts(parts)
    v = len(canonical)
    return Person(v, np.concatenate([head.triangles, extras.triangles + v]).astype(np.int32),
                  np.concatenate([canonical, extras.canonical]).astype(np.float32),
                  np.concatenate([material, extras.material]).astype(np.float32), extras, frame)
