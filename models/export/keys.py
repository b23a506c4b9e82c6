"""Keyframed channels as glTF animation samplers.

An animation file (app/animation.py) keys each channel at its own times and plays it back linearly or smoothly:
between keys (t0, v0) and (t1, v1), v(t) = v0 + (v1 - v0) e(u), u = (t - t0) / (t1 - t0), with e(u) = u (linear) or
e(u) = 3u^2 - 2u^3 (smooth: at rest at each key); before the first key and after the last the channel holds.

glTF plays a morph-weight sampler as one curve over all the weights, at one set of times. Both kinds of key come
through exactly at the union of the channels' key times:
- linear: glTF's LINEAR sampler between the values there (a channel's line through another's key is still a line);
- smooth: glTF's CUBICSPLINE (glTF 2.0, Appendix C), the Hermite cubic
  p(s) = (2s^3 - 3s^2 + 1) v_k + dt (s^3 - 2s^2 + s) b_k + (-2s^3 + 3s^2) v_k+1 + dt (s^3 - s^2) a_k+1,
  with the out-tangent b_k and in-tangent a_k+1 the channel's derivatives there (per second): a smoothstep is that
  cubic with tangents 0 at its keys, and cut at another channel's key each piece is a cubic with the derivatives at
  its ends as tangents.
Rotations (head, neck, jaw, eyes) are sampled at the animation's frames, as `animate` renders them, and played back
by glTF's LINEAR (spherical) interpolation between frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from models.export.skeleton import quaternions

Interpolation = Literal["linear", "smooth"]


def channel_samples(keys: Sequence[tuple[float, float]], times: np.ndarray, interpolation: Interpolation
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A keyed channel's values at `times` (T,), seconds, and its derivatives there arriving and leaving (per second):
    (values, in_slopes, out_slopes), each (T,). keys: (time, value) pairs in time order.

    >>> v, d_in, d_out = channel_samples([(0.0, 0.0), (2.0, 1.0)], np.array([0.0, 1.0, 2.0, 3.0]), "smooth")
    >>> v.tolist(), d_in.tolist(), d_out.tolist()  # halfway: e(1/2) = 1/2, e'(1/2) = 6/4, over 2 s: 0.75 a second
    ([0.0, 0.5, 1.0, 1.0], [0.0, 0.75, 0.0, 0.0], [0.0, 0.75, 0.0, 0.0])
    >>> channel_samples([(0.0, 0.0), (2.0, 1.0)], np.array([0.0, 2.0]), "linear")[1:]  # 0.5 a second within
    (array([0. , 0.5]), array([0.5, 0. ]))
    """
    t_keys = np.array([k[0] for k in keys], np.float64)
    v_keys = np.array([k[1] for k in keys], np.float64)
    times = np.asarray(times, np.float64)
    values = np.empty(len(times))
    slopes = np.zeros((2, len(times)))  # arriving, leaving
    for n, t in enumerate(times):
        values[n] = value_at(t_keys, v_keys, t, interpolation)
        for side, seg in enumerate((np.searchsorted(t_keys, t, "left") - 1, np.searchsorted(t_keys, t, "right") - 1)):
            if 0 <= seg < len(t_keys) - 1 and t_keys[seg + 1] > t_keys[seg]:
                dt = t_keys[seg + 1] - t_keys[seg]
                u = (t - t_keys[seg]) / dt
                ease_slope = 1.0 if interpolation == "linear" else 6.0 * u * (1.0 - u)
                slopes[side, n] = (v_keys[seg + 1] - v_keys[seg]) / dt * ease_slope
    return values, slopes[0], slopes[1]


def value_at(t_keys: np.ndarray, v_keys: np.ndarray, t: float, interpolation: Interpolation) -> float:
    """A channel's value at time t (app/animation.py's Animation.value, whose tests hold this to it)."""
    if t <= t_keys[0]:
        return float(v_keys[0])
    seg = int(np.searchsorted(t_keys, t, "left")) - 1
    if seg >= len(t_keys) - 1:
        return float(v_keys[-1])
    dt = t_keys[seg + 1] - t_keys[seg]
    u = (t - t_keys[seg]) / dt if dt > 0 else 1.0
    e = u if interpolation == "linear" else u * u * (3.0 - 2.0 * u)
    return float(v_keys[seg] + (v_keys[seg + 1] - v_keys[seg]) * e)


@dataclass(frozen=True, eq=False)
class MorphKeys:
    """The morph weights' sampler: every expression's weight at the keyed channels' key times."""

    times: np.ndarray  # (K,) seconds, increasing
    values: np.ndarray  # (K,E) weights
    in_tangents: np.ndarray  # (K,E) per second (CUBICSPLINE only)
    out_tangents: np.ndarray  # (K,E)
    interpolation: Literal["LINEAR", "CUBICSPLINE"]


@dataclass(frozen=True, eq=False)
class PoseFrames:
    """Joint rotations sampled at the animation's frames."""

    times: np.ndarray  # (N,) seconds, increasing
    rotations: dict[int, np.ndarray]  # joint index -> (N,4) quaternions (x, y, z, w)


@dataclass(frozen=True, eq=False)
class Clip:
    """One glTF animation."""

    name: str
    morph: MorphKeys | None
    pose: PoseFrames | None


def morph_keys(tracks: dict[int, Sequence[tuple[float, float]]], n_expressions: int,
               interpolation: Interpolation) -> MorphKeys | None:
    """The sampler of keyed expressions (expression index -> keys; the rest stay 0) at the union of their key
    times; None where no expression is keyed."""
    if not tracks:
        return None
    times = np.unique(np.concatenate([[k[0] for k in keys] for keys in tracks.values()]))
    values, d_in, d_out = (np.zeros((len(times), n_expressions)) for _ in range(3))
    for e, keys in tracks.items():
        values[:, e], d_in[:, e], d_out[:, e] = channel_samples(keys, times, interpolation)
    f = lambda a: a.astype(np.float32)
    return MorphKeys(f(times), f(values), f(d_in), f(d_out), "LINEAR" if interpolation == "linear" else "CUBICSPLINE")


def pose_frames(times: np.ndarray, full_pose: np.ndarray) -> PoseFrames | None:
    """The rotations of the joints that turn at some frame (full_pose (N,J,3) axis-angle per joint, radians, at
    `times` (N,)) as quaternions; None where none turns."""
    turning = [j for j in range(full_pose.shape[1]) if np.any(full_pose[:, j] != 0)]
    if not turning:
        return None
    return PoseFrames(np.asarray(times, np.float32), {j: quaternions(full_pose[:, j]) for j in turning})
