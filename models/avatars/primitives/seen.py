"""How far inside the capture's frames each texel of the primitives' chart ever came, and the fade of opacity that
follows from it: where the capture stopped seeing the head (the bottom of a portrait's frame cuts the neck and
shoulders), the primitives beyond were never trained, and from any other camera their untrained opacity is a
ragged cut of boxes. They fade out instead, over EDGE_SHARE of the frame's size past the edge.
"""

from __future__ import annotations

import numpy as np
import torch

from render.camera import Camera, project

EDGE_SHARE = 0.06
"""A texel that came no nearer than this share of the frame's larger side to the inside of any frame has no opacity;
one that lay inside some frame keeps all of it; between, a smooth step (16 px at 256 px)."""


def inside_share(points: np.ndarray, camera: Camera) -> np.ndarray:
    """(T,) how far inside a camera's frame points (T,3) project, as a share of its larger side: the distance to the
    nearest edge (negative outside the frame; -inf behind the camera).

    >>> cam = Camera.from_intrinsics(np.eye(4), 100.0, 100.0, 50.0, 50.0, 100, 100)
    >>> p = np.array([[0.0, 0, -1], [0.25, 0, -1], [0.6, 0, -1], [0, 0, 1]])
    >>> [round(x, 6) for x in inside_share(p, cam).tolist()]  # centre, 25 px in, 10 px out, behind
    [0.5, 0.25, -0.1, -inf]
    """
    u, v, depth = project(camera, points)
    w, h = camera.width_px, camera.height_px
    edge = np.minimum(np.minimum(u, w - u), np.minimum(v, h - v)) / max(w, h)
    return np.where(depth > 1e-6, edge, -np.inf)


def edge_fade(reach: torch.Tensor, edge_share: float = EDGE_SHARE) -> torch.Tensor:
    """(T,) 1 where a texel lay inside some frame (reach >= 0), 0 where it stayed edge_share or more outside every
    one, a smooth step (3 s^2 - 2 s^3) between.

    >>> edge_fade(torch.tensor([0.3, 0.0, -0.03, -0.06, -float("inf")])).tolist()
    [1.0, 1.0, 0.5, 0.0, 0.0]
    """
    s = (reach / edge_share + 1.0).clamp(0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)
