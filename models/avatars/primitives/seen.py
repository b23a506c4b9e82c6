"""How far inside the capture's frames each texel of the primitives' chart ever came, and the fade of opacity that
follows from it: where the capture stopped seeing the head (the bottom of a portrait's frame cuts the neck and
shoulders), the primitives beyond were never trained, and from any other camera their untrained opacity is a
ragged cut of boxes. They fade out instead, over EDGE_SHARE of the frame's size past the edge.
"""

from __future__ import annotations

import torch

EDGE_SHARE = 0.06
"""A texel that came no nearer than this share of the frame's larger side to the inside of any frame has no opacity;
one that lay inside some frame keeps all of it; between, a smooth step (16 px at 256 px)."""


def inside_share(points: torch.Tensor, world_to_camera: torch.Tensor, intrinsics: torch.Tensor, width: int,
                 height: int) -> torch.Tensor:
    """(T,) how far inside a pinhole frame points (T,3) project, as a share of its larger side: the distance to the
    nearest edge (negative outside the frame; -inf behind the camera). OpenGL axes (-z ahead, +y up), rows top
    first; intrinsics (fx, fy, cx, cy) in pixels.

    >>> I = torch.eye(4); K = torch.tensor([100.0, 100.0, 50.0, 50.0])
    >>> p = torch.tensor([[0.0, 0, -1], [0.25, 0, -1], [0.6, 0, -1], [0, 0, 1]])
    >>> [round(x, 6) for x in inside_share(p, I, K, 100, 100).tolist()]  # centre, 25 px in, 10 px out, behind
    [0.5, 0.25, -0.1, -inf]
    """
    cam = points @ world_to_camera[:3, :3].T + world_to_camera[:3, 3]
    ahead = -cam[:, 2]
    depth = ahead.clamp_min(1e-9)
    fx, fy, cx, cy = intrinsics.unbind()
    u = cx + fx * cam[:, 0] / depth
    v = cy - fy * cam[:, 1] / depth
    edge = torch.stack([u, width - u, v, height - v], -1).min(-1).values / max(width, height)
    return torch.where(ahead > 1e-6, edge, torch.full_like(edge, -torch.inf))


def edge_fade(reach: torch.Tensor, edge_share: float = EDGE_SHARE) -> torch.Tensor:
    """(T,) 1 where a texel lay inside some frame (reach >= 0), 0 where it stayed edge_share or more outside every
    one, a smooth step (3 s^2 - 2 s^3) between.

    >>> edge_fade(torch.tensor([0.3, 0.0, -0.03, -0.06, -float("inf")])).tolist()
    [1.0, 1.0, 0.5, 0.0, 0.0]
    """
    s = (reach / edge_share + 1.0).clamp(0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)
