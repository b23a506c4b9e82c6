"""Live driving: each camera frame's face, as it comes, to an avatar's channel values.

No fit over the whole performance (as `reenact` runs) can wait for frames not yet filmed, so a frame's controls come
from what the face landmarker gives for that frame alone: expressions, jaw and gaze from its blendshape scores
(models/tracking/blendshapes.py, the fit's own starting point) and the head's rotation from its facial
transformation matrix. They are carried onto the avatar relative to a neutral frame (the first face seen, or the one
at hand when the neutral is set again) by the retargeting `reenact` uses (models/tracking/retarget.py), and
smoothed by a One Euro filter (models/tracking/smoothing.py): still faces do not jitter, moving ones are followed
without visible lag.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from models.head.controls import Controls
from models.head.model import HeadModel
from models.tracking.blendshapes import expression_from_scores, gaze_from_scores, jaw_from_scores
from models.tracking.landmarker import Face
from models.tracking.retarget import Carry, Limits, frame_channels
from models.tracking.smoothing import OneEuro


def face_rotation(pose: np.ndarray) -> np.ndarray:
    """(3,) axis-angle of the rotation in MediaPipe's facial transformation matrix (4,4), its 3x3 block made
    orthonormal (the nearest rotation: U V^T of its SVD, which drops any scale the matrix carries).

    >>> r = Rotation.from_euler("YXZ", [20, -5, 3], degrees=True).as_matrix()
    >>> m = np.eye(4); m[:3, :3] = 1.1 * r; m[:3, 3] = [1, 2, -40]
    >>> np.round(Rotation.from_rotvec(face_rotation(m)).as_euler("YXZ", degrees=True), 6).tolist()
    [20.0, -5.0, 3.0]
    """
    u, _, vt = np.linalg.svd(np.asarray(pose, np.float64)[:3, :3])
    r = u @ vt
    if np.linalg.det(r) < 0:  # a reflection: flip the least singular direction
        u[:, -1] *= -1
        r = u @ vt
    return Rotation.from_matrix(r).as_rotvec().astype(np.float32)


def controls_from_face(face: Face, head: HeadModel) -> Controls:
    """One frame's controls in the head model's terms: expressions, jaw and gaze from the blendshape scores, the
    root rotation from the face's transformation matrix (no translation: live driving does not carry it)."""
    gaze = gaze_from_scores(face.blendshapes)
    return Controls(expression=expression_from_scores(head, face.blendshapes), root=face_rotation(face.pose),
                    jaw=jaw_from_scores(face.blendshapes), gaze_left=gaze[0], gaze_right=gaze[1])


DEGREE_CHANNELS = ("head.", "jaw.", "gaze.")
"""Channels in degrees (the rest are expression weights)."""


@dataclass(frozen=True)
class LiveSmoothing:
    """The One Euro filter's settings for live channels."""

    min_cutoff_hz: float = 1.5
    """The cutoff while the face holds still (jitter above it is removed)."""
    beta_weights: float = 5.0
    """The cutoff's rise per unit/s of an expression weight's speed."""
    beta_degrees: float = 0.2
    """... per degree/s of an angle's speed (a 20 degrees/s turn adds 4 Hz; a jaw opening 12 degrees in a frame at
    30 fps, about 14 Hz: three quarters of the way in that frame). Weights span about 1, angles about 25 degrees:
    beta_weights is 25 times this."""
    d_cutoff_hz: float = 1.0
    """The cutoff of the speed estimate."""


class LiveRetarget:
    """A stream of faces to the avatar's channel values, relative to the neutral frame, smoothed."""

    def __init__(self, head: HeadModel, limits: Limits, smoothing: LiveSmoothing = LiveSmoothing()):
        self.head, self.limits, self.smoothing = head, limits, smoothing
        self.carry: Carry | None = None
        self.names: list[str] = []
        self.filter = OneEuro(smoothing.min_cutoff_hz, 0.0, smoothing.d_cutoff_hz)

    def set_neutral(self) -> None:
        """The next face becomes the neutral one (its expression the avatar's rest)."""
        self.carry = None

    def __call__(self, face: Face, t_s: float) -> dict[str, float]:
        """The channels of the face seen at t_s (seconds, increasing), smoothed."""
        c = controls_from_face(face, self.head)
        if self.carry is None:
            self.carry = Carry.of(c, self.head, self.head)
            self.filter.reset()
        raw = frame_channels(c, self.carry, self.limits)
        if list(raw) != self.names:
            s = self.smoothing
            self.names = list(raw)
            self.filter = OneEuro(s.min_cutoff_hz, np.array([s.beta_degrees if n.startswith(DEGREE_CHANNELS)
                                                             else s.beta_weights for n in self.names]),
                                  s.d_cutoff_hz)
        smooth = self.filter(np.array([raw[n] for n in self.names]), t_s)
        return {n: float(v) for n, v in zip(self.names, smooth, strict=True)}
