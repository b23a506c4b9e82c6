"""What moves with the body behind the head, in the capture's own camera: the shoulders, the collar, the top and
the hair that lies on them.

A head model ends at the neck. Below it a video shows the person's clothes, which move with the body, not with the
room: the background plate (plate.py) is the room, and where the body covered it in every frame it holds a guess.
A held-out frame where the body has moved, or where the camera drew back or zoomed out (more of the top in view
than any training frame showed), then shows the plate's guess where the video shows the clothes.

The body layer is a flat picture (RGB and opacity, TEXELS x TEXELS over EXTENT_M) standing at the neck, facing
where the head model's face looks, turned with the torso (the root joint: models/tracking/torso.py). It lies behind
the head's primitives and in front of the plate: each ray of the capture's camera meets its plane once, and what it
shows there is composited over the plate before the primitives over both. It is trained with the avatar (the same
photometric loss through the background the march composites). Texels no training ray reached take their nearest
taught texels' values, averaged (`source`, made when the views are noted; FILL_BLUR): the clothes continue below the
lowest edge a training frame showed, so a frame drawn back shows more of the top, not the room. Only rays that carry
the plate (the capture's camera) see it: a turntable or an orbit has no room behind the head, and no flat picture
there.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

TEXELS = 128
"""The layer's texels a side."""
EXTENT_M = (-0.45, 0.45, -0.6, 0.3)
"""The layer's extent in its plane, metres from the neck joint: (left, right, bottom, top) along the torso's x and
y axes (7 mm a texel across, 7 down); beyond it the edge's texels continue."""
START_OPACITY_LOGIT = -4.0
"""The layer starts nearly clear (1.8% opaque), the plate showing through until the frames say otherwise. A texel no
training ray reaches (the room far from the person) shows its nearest taught texel (`source`), not this start's haze
over the room. Started at -9 (clear) it learnt too slowly: `portrait_seaside` at 10 minutes 21.79 dB held out
against 22.86 (docs/results.md)."""
BODY_LR_SCALE = 4.0
"""The texture learns at this many times the networks' rate (at 5e-3 a texel moves 0.02 in logit a step)."""
FILL_BLUR = 9
"""Texels no training ray reached show the mean of their nearest taught texels' values over this many texels a side
(6 cm): the clothes' colour continues, not the last row's pattern drawn out in streaks."""
GRAZING = 1e-3
"""A ray whose direction's cosine with the plane's normal is below this misses it."""


class BodyLayer(nn.Module):
    """The layer's texture (1,4,T,T): colour and opacity logits, rows from the top; `source` (T*T,) the texel each
    one shows (its nearest seen texel; itself where seen, and every texel itself until the views are noted), and
    `unseen` (1,1,T,T), where it is not itself or None where every texel is (derived from source, not saved)."""

    def __init__(self, texels: int = TEXELS):
        super().__init__()
        texture = torch.zeros(1, 4, texels, texels)
        texture[:, 3] = START_OPACITY_LOGIT
        self.texture = nn.Parameter(texture)
        self.register_buffer("source", torch.arange(texels * texels))
        self.register_buffer("unseen", None, persistent=False)

    def note_unseen(self) -> None:
        """`unseen` from `source`, once (not on every step's shown())."""
        T = self.texels
        unseen = (self.source != torch.arange(T * T, device=self.source.device)).reshape(1, 1, T, T)
        self.register_buffer("unseen", unseen if bool(unseen.any()) else None, persistent=False)

    def _load_from_state_dict(self, *args, **kwargs):
        super()._load_from_state_dict(*args, **kwargs)
        self.note_unseen()

    @property
    def texels(self) -> int:
        return self.texture.shape[-1]

    def plane_coordinates(self, origins: torch.Tensor, directions: torch.Tensor, body: tuple[torch.Tensor, torch.Tensor]
                          ) -> tuple[torch.Tensor, torch.Tensor]:
        """(R,2) where rays (R,3) meet the layer's plane, in texture coordinates (x right, y down, -1..1 over
        EXTENT_M, beyond it outside the extent, held to +-2; 2 where a ray misses), and (R,) whether they meet it
        (in front of the camera, not grazing). body: the plane's origin (3,) and axes (3,3, columns x, y, normal) in
        the world."""
        centre, axes = (t.to(directions) for t in body)
        along = directions @ axes  # (R,3): each direction along the plane's x, y and normal
        at = (origins - centre) @ axes  # where each origin stands in the plane's frame
        facing = along[:, 2]
        hit = facing.abs() >= GRAZING
        s = -at[:, 2] / torch.where(hit, facing, torch.full_like(facing, GRAZING))
        hit = hit & (s > 0)
        uv = at[:, :2] + s.clamp_min(0.0)[:, None] * along[:, :2]
        left, right, bottom, top = EXTENT_M
        scale = uv.new_tensor([2.0 / (right - left), -2.0 / (top - bottom)])
        shift = uv.new_tensor([-2.0 * left / (right - left) - 1.0, 2.0 * top / (top - bottom) - 1.0])
        xy = (uv * scale + shift).clamp(-2.0, 2.0)  # far beyond: the edge (grid_sample clamps to the border)
        return torch.where(hit[:, None], xy, torch.full_like(xy, 2.0)), hit

    def shown(self) -> torch.Tensor:
        """(1,4,T,T) the texture as it shows: a seen texel its own value, an unseen one its nearest seen texel's
        neighbourhood (`source`, averaged over FILL_BLUR texels)."""
        T = self.texels
        filled = self.texture.reshape(1, 4, T * T)[:, :, self.source].reshape(1, 4, T, T)
        if self.unseen is None:
            return filled
        soft = F.avg_pool2d(filled, FILL_BLUR, stride=1, padding=FILL_BLUR // 2, count_include_pad=False)
        return torch.where(self.unseen, soft, filled)

    def over(self, background: torch.Tensor, origins: torch.Tensor, directions: torch.Tensor,
             body: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
        """(R,3) the layer composited over what each ray saw behind it (R,3)."""
        xy, hit = self.plane_coordinates(origins, directions, body)
        texel = F.grid_sample(self.shown(), xy[None, :, None].to(self.texture), mode="bilinear",
                              padding_mode="border", align_corners=False)[0, :, :, 0].T  # (R,4)
        colour = torch.sigmoid(texel[:, :3])
        alpha = torch.sigmoid(texel[:, 3:]) * hit[:, None].to(texel)
        return alpha * colour.to(background) + (1.0 - alpha) * background

    @torch.no_grad()
    def note_seen(self, seen: np.ndarray) -> None:
        """Every texel shows its nearest seen one (seen (T,T) bool: some training frame's pixel fell on it); where
        none was seen, each itself."""
        from scipy.ndimage import distance_transform_edt

        seen = np.asarray(seen, bool)
        T = self.texels
        if not seen.any():
            self.source.copy_(torch.arange(T * T))
        else:
            _, (rows, cols) = distance_transform_edt(~seen, return_indices=True)
            self.source.copy_(torch.as_tensor((rows * T + cols).ravel()))
        self.note_unseen()

    def texel_centres(self, body: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
        """(T*T,3) the world points of the texels' centres, rows from the top (the plane at body: its origin and axes,
        as plane_coordinates)."""
        T = self.texels
        left, right, bottom, top = EXTENT_M
        centre, axes = body
        x = left + (torch.arange(T, dtype=axes.dtype, device=axes.device) + 0.5) * (right - left) / T
        y = top - (torch.arange(T, dtype=axes.dtype, device=axes.device) + 0.5) * (top - bottom) / T
        yy, xx = torch.meshgrid(y, x, indexing="ij")
        return centre + xx.reshape(-1, 1) * axes[:, 0] + yy.reshape(-1, 1) * axes[:, 1]


def body_frame(joints: torch.Tensor, root_rotation: torch.Tensor, joint_names: tuple[str, ...]
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """The layer's plane for a posed frame: its origin at the neck joint (the root where a model has no neck), its
    axes (3,3, columns: x, y, normal) the root's rotation of the head model's own (x right, y up, z where the face
    looks). joints (J,3) posed, root_rotation (3,3)."""
    at = joint_names.index("neck") if "neck" in joint_names else 0
    return joints[at], root_rotation
