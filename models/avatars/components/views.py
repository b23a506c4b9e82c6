"""The directions a capture saw the head from, and new views held to them.

A colour network that reads the view direction learns it only over the directions its capture's rays came
from, and a turntable or the studio's camera sliders ask it for others: on the tracked d3 video (`all`, 30
minutes, captured yaws -22.8 to 14.3 degrees) a camera turned 20 degrees to the subject's left washed the face out
to grey, where the same render with the view held to the capture camera's axis kept her colours (the density,
which reads no view, is the same in both). Two rules, by what the model reads (models/avatars/base.py):

- a colour read per sample (CoDyNeRF, NerFACE) on a capture whose camera stood still (a tracked video): one
  camera saw every point from one direction, the way to that camera, so that is the direction the colour reads
  whatever camera renders (`CaptureViews.towards_camera`);
- a view read once a frame (the primitives' decoder, in the head's frame): held to the cone of the training
  frames' views (`view_cone`, `into_cone`; `CaptureViews.seen`): its axis and the largest angle from it, plus a
  margin; a direction outside moves to the nearest direction on the rim, in the plane of the direction and the
  axis.

Directions the capture gave are untouched either way: its own frames render exactly as before. A capture that saw
the head from all round (the mean direction shorter than a few percent, or a cone wider than a hemisphere) gets
no cone.
"""

from __future__ import annotations

import math
from typing import ClassVar

import torch

from models.avatars.components.kept import Kept

MARGIN_DEG = 2.0
"""Added to the widest training direction: pose corrections turn a tracked video's rays by a fraction of it."""


def view_cone(towards: torch.Tensor, margin_deg: float = MARGIN_DEG) -> tuple[torch.Tensor, float] | None:
    """The cone (unit axis (3,), cosine of its half-angle) holding every unit direction of (N,3) `towards` (from
    the head towards the camera) with margin_deg to spare; None where they come from all round.

    >>> axis, cos = view_cone(torch.tensor([[0.0, 0.0, 1.0], [math.sin(0.1), 0.0, math.cos(0.1)]]), margin_deg=0)
    >>> [round(v, 4) for v in axis.tolist()], round(math.degrees(math.acos(cos)), 3)
    ([0.05, 0.0, 0.9988], 2.865)
    """
    v = towards.detach().double()
    v = v[torch.isfinite(v).all(-1)]
    if len(v) == 0:
        return None
    v = v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    mean = v.mean(0)
    if mean.norm() < 0.05:
        return None
    axis = mean / mean.norm()
    half = math.acos(float((v @ axis).min().clamp(-1, 1))) + math.radians(margin_deg)
    if half >= math.pi / 2:
        return None
    return axis.float(), math.cos(half)


def into_cone(v: torch.Tensor, axis: torch.Tensor, cos_max: float) -> torch.Tensor:
    """(N,3) unit directions, those outside the cone moved to its rim towards them (a direction opposite the
    axis: to the rim on the side of the smallest component of the axis).

    A direction 90 degrees from the axis, into a cone of 60: to 60 degrees, in their plane.
    >>> into_cone(torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), torch.tensor([0.0, 0.0, 1.0]), 0.5)
    tensor([[0.8660, 0.0000, 0.5000],
            [0.0000, 0.0000, 1.0000]])
    """
    # Worked in double: a direction nearly opposite the axis leaves a side component of order 1e-3 after
    # cancellation, too few float bits for a unit vector in the axis's plane. The side is made orthogonal to
    # the axis again after it is normalised, and the rim normalised last.
    a = axis.to(v).double()
    a = a / a.norm()
    u = v.double()
    c = u @ a
    side = u - c[:, None] * a
    length = side.norm(dim=-1, keepdim=True)
    spare = torch.zeros_like(a)
    spare[int(a.abs().argmin())] = 1.0
    spare = spare - (spare @ a) * a
    side = torch.where(length > 1e-9, side / length.clamp_min(1e-9), spare / spare.norm())
    side = side - (side @ a)[:, None] * a
    side = side / side.norm(dim=-1, keepdim=True)
    rim = cos_max * a + math.sqrt(max(0.0, 1.0 - cos_max * cos_max)) * side
    rim = (rim / rim.norm(dim=-1, keepdim=True)).to(v.dtype)
    inside = v @ axis.to(v) >= cos_max  # in the caller's precision: what it holds inside stays bit for bit
    return torch.where(inside[:, None], v, rim)


class CaptureViews(Kept):
    """Where the capture's camera stood if it stood still (a tracked video: `eye`) and the cone of the views a
    model read once a frame (`axis`, `cos`); none of them for a capture that gave none (saved with the weights)."""

    weight_names: ClassVar[dict[str, str]] = {"eye": "capture_eye", "axis": "view_axis", "cos": "view_cos"}

    def note(self, origins: torch.Tensor, views: torch.Tensor | None, device: torch.device | str = "cpu") -> None:
        """Remember the capture's camera where its rays' origins (N,3) stand still, and the cone of the views (N,3)
        (towards the camera, in the frame the model reads them) where the model reads one a frame (else None)."""
        if len(origins) and float((origins - origins[0]).norm(dim=-1).max()) < 1e-4:
            self.keep("eye", origins[0].float().clone().to(device))
        cone = None if views is None else view_cone(views)
        if cone is not None:
            self.keep("axis", cone[0].to(device))
            self.keep("cos", torch.tensor(cone[1], dtype=torch.float32, device=device))

    def seen(self, towards: torch.Tensor) -> torch.Tensor:
        """(N,3) view directions (towards the camera), held to the capture's cone where there is one."""
        return towards if self.axis is None else into_cone(towards, self.axis, float(self.cos))

    def towards_camera(self, points: torch.Tensor) -> torch.Tensor | None:
        """(P,3) unit directions from world points to the capture's camera where it stood still, else None.

        One fixed camera saw every point of the head from one direction only, the way to that camera (the head
        turned, the camera did not): a colour network that reads the view learnt it there and nowhere else. So
        on such a capture the view it reads is that direction whatever camera renders: along the capture
        camera's own rays it is the ray's direction reversed (the same input as before), and a turntable or
        an orbit of the studio's camera no longer asks it for views it never saw."""
        if self.eye is None:
            return None
        v = self.eye.to(points) - points
        return v / v.norm(dim=-1, keepdim=True).clamp_min(1e-9)
