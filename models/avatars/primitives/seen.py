"""How far inside the capture's frames each texel of the primitives' chart ever came, and the fade of opacity that
follows from it: where the capture stopped seeing the head (the bottom of a portrait's frame cuts the neck and
shoulders), the primitives beyond were never trained, and from any other camera their untrained opacity is a
ragged cut of boxes. They fade out instead, over EDGE_SHARE of the frame's size past the edge.

And a fade down the neck (neck_fade), for primitives shown where no video looked (a whole head's outside): there
the neck's lowest boxes ended in their faces, a straight cut with blocks of the collar's colours below the hair.
"""

from __future__ import annotations

import numpy as np
import torch

from models.head.model import HeadModel
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


NECK_FADE_M = (0.12, 0.18)
"""neck_fade: all of the density down to 0.12 m below the eyes' height in the head's own frame, none from 0.18, a smooth
step between (3 s^2 - 2 s^3). The chin lies 0.106-0.112 m below the eyes on the tracked built-in heads of four shared
clips (a child's, three adults'), so the neck shows from 1 cm under the chin and is gone 7 cm under it (0.14-0.21
left the child's top, in pink blocks, under her hair from behind)."""


def eye_height_m(head_model: HeadModel) -> float | None:
    """The eyes' joints' mean height (y) in the head model's template, or None where it has no eye joints."""
    names = head_model.joint_names
    if "eye_l" not in names or "eye_r" not in names:
        return None
    joints = np.asarray(head_model.J_regressor, np.float64) @ np.asarray(head_model.template, np.float64)
    return float(0.5 * (joints[names.index("eye_l"), 1] + joints[names.index("eye_r"), 1]))


def height_fade(height: torch.Tensor, eyes_m: float, band: tuple[float, float] = NECK_FADE_M) -> torch.Tensor:
    """1 at heights (any shape, metres in the head's frame) band[0] or less below eyes_m, 0 band[1] or more below it,
    a smooth step between.

    >>> [round(x, 6) for x in height_fade(torch.tensor([0.1, -0.12, -0.15, -0.18, -1.0]), 0.0).tolist()]
    [1.0, 1.0, 0.5, 0.0, 0.0]
    """
    s = ((height - (eyes_m - band[1])) / (band[1] - band[0])).clamp(0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def voxel_heights(centres: torch.Tensor, rotations: torch.Tensor, half_sizes: torch.Tensor, voxels: int,
                  rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """(P,M,M,M) [z, y, x] the height (y) in the head's frame of each voxel centre of P boxes (centres (P,3),
    rotations (P,3,3) columns their axes, half_sizes (P,3), in the world; voxel centres at -1 + 2k/(M-1) of each
    axis, as the lookups read them), the head's frame given by its rigid pose (rotation (3,3) head -> world,
    translation (3,)): a box's heights are its centre's plus each axis's rise, so no voxel's point is made."""
    up = rotation[:, 1].to(centres)
    g = torch.linspace(-1.0, 1.0, voxels, dtype=centres.dtype, device=centres.device) if voxels > 1 \
        else torch.zeros(1, dtype=centres.dtype, device=centres.device)
    rise = (rotations * up[None, :, None]).sum(1) * half_sizes  # (P,3): each axis's rise over its half-size
    base = (centres - translation.to(centres)) @ up
    return (base[:, None, None, None] + rise[:, 2, None, None, None] * g[None, :, None, None]
            + rise[:, 1, None, None, None] * g[None, None, :, None] + rise[:, 0, None, None, None] * g)


def edge_fade(reach: torch.Tensor, edge_share: float = EDGE_SHARE) -> torch.Tensor:
    """(T,) 1 where a texel lay inside some frame (reach >= 0), 0 where it stayed edge_share or more outside every
    one, a smooth step (3 s^2 - 2 s^3) between.

    >>> edge_fade(torch.tensor([0.3, 0.0, -0.03, -0.06, -float("inf")])).tolist()
    [1.0, 1.0, 0.5, 0.0, 0.0]
    """
    s = (reach / edge_share + 1.0).clamp(0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)
