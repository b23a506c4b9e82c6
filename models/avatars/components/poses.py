"""Per-frame corrections of a tracked video's head poses (and, for models that pose their guide mesh each step,
its expressions), learned with the avatar.

A tracker's head pose is off by a fraction of a degree and a millimetre or two from frame to frame, and an avatar
that takes the poses as given learns a head smeared by that jitter. Each training frame gets a rotation (axis-angle,
about the head's centre) and a translation (metres); the rays of that frame are moved into the tracked head's frame
where the head truly stood. The corrections are zero-mean over the frames (the avatar keeps the tracker's poses on
average, and held-out frames and new controls, which nothing is fitted to, use the poses as tracked), held by a
squared prior in units of 0.01 rad and 2 mm, learn at POSE_LR_SCALE of the networks' rate, and are saved with the
weights (`pose_corrections`; avatar.json says whether an avatar has them).

Expression corrections (`expression_corrections`, (N,E)) are the same for the head model's expression weights: the
tracker fits a few dozen landmarks, and the mouth's and eyelids' shapes between them are a guess; a model whose
primitives sit on the posed mesh (the primitives) poses the mesh with the corrected weights and reads them as its
condition. Zero-mean over the frames, a squared prior in units of PRIOR_EXPRESSION, POSE_LR_SCALE's rate times
EXPRESSION_LR_RATIO, and only on training frames, as the poses'.
"""

from __future__ import annotations

from dataclasses import replace

import torch
from torch import nn

from models.head.lbs import rotation_matrix_from_axis_angle
from models.head.model import HeadModel
from render.rays import Rays

POSE_LR_SCALE = 0.02
"""The pose corrections' learning rate against the networks' (Adam moves each by about its rate a step)."""
PRIOR_RAD = 0.01
PRIOR_M = 0.002
PRIOR_EXPRESSION = 0.1
"""An expression weight's correction, in units of this (weights run 0 to 1)."""
EXPRESSION_LR_RATIO = 5.0
"""Expression weights span 0 to 1, the poses' hundredths of a radian: their corrections learn this much faster."""


class PoseCorrected:
    """Mixin for an Avatar (an nn.Module with `n_frames`) whose training frames' poses may be corrected; its
    __init__ sets `self.pose_corrections = None` and `self.expression_corrections = None` (the frames as given)."""

    pose_corrections: nn.Parameter | None
    expression_corrections: nn.Parameter | None
    n_frames: int
    head_model: HeadModel

    def correct_poses(self) -> None:
        """Give every training frame a pose correction (N,6), learned with the avatar."""
        if self.pose_corrections is None:
            device = next(self.parameters()).device
            self.pose_corrections = nn.Parameter(torch.zeros(self.n_frames, 6, device=device))

    def corrections_meta(self) -> dict:
        """avatar.json's record of which corrections the weights hold."""
        return {"pose_corrections": self.pose_corrections is not None,
                "expression_corrections": self.expression_corrections is not None}

    def restore_corrections(self, meta: dict) -> None:
        """Make the corrections avatar.json says the weights hold (before they are loaded)."""
        if meta.get("pose_corrections", False):
            self.correct_poses()
        if meta.get("expression_corrections", False):
            self.correct_expressions(self.head_model.num_expression)

    def correct_expressions(self, count: int) -> None:
        """Give every training frame a correction of its `count` expression weights (N,count), learned with the
        avatar."""
        if self.expression_corrections is None:
            device = next(self.parameters()).device
            self.expression_corrections = nn.Parameter(torch.zeros(self.n_frames, count, device=device))

    def parameter_groups(self) -> list[dict]:
        """The pose corrections learn at POSE_LR_SCALE of the rate of the networks (a step of the networks' rate,
        5e-3, would turn the head by 0.3 degrees and move it 5 mm at once), the expressions' EXPRESSION_LR_RATIO
        times faster."""
        own = [(p, s) for p, s in ((self.pose_corrections, POSE_LR_SCALE),
                                   (self.expression_corrections, POSE_LR_SCALE * EXPRESSION_LR_RATIO))
               if p is not None]
        if not own:
            return super().parameter_groups()
        mine = {id(p) for p, _ in own}
        rest = [p for p in self.parameters() if id(p) not in mine]
        return [{"params": rest, "lr_scale": 1.0}, *({"params": [p], "lr_scale": s} for p, s in own)]

    def pose_correction(self, frame: int) -> torch.Tensor:
        """(6,) a training frame's correction less the mean of all frames'."""
        return self.pose_corrections[frame] - self.pose_corrections.mean(0)

    def pose_centre(self, geometry) -> torch.Tensor:
        """(3,) the point of a frame's geometry the corrections turn the head about: its centre."""
        raise NotImplementedError

    def corrected_rays(self, rays: Rays, geometry, frame: int) -> Rays:
        """The rays in the tracked head's frame where the head truly stood at `frame`: the head turned by r about
        its centre c (pose_centre) and moved by t maps a world point p to R^T (p - c - t) + c."""
        centre = self.pose_centre(geometry)
        c = self.pose_correction(frame)
        rot = rotation_matrix_from_axis_angle(c[:3])
        origins = (rays.origins - centre - c[3:]) @ rot + centre  # row vectors: p @ R = R^T p
        return replace(rays, origins=origins, directions=rays.directions @ rot)

    def pose_correction_term(self, frame: int) -> torch.Tensor:
        """The corrections' prior: squared, in units of PRIOR_RAD and PRIOR_M."""
        c = self.pose_correction(frame)
        return (c[:3] / PRIOR_RAD).square().sum() + (c[3:] / PRIOR_M).square().sum()

    def expression_correction(self, frame: int) -> torch.Tensor:
        """(E,) a training frame's expression correction less the mean of all frames'."""
        return self.expression_corrections[frame] - self.expression_corrections.mean(0)

    def expression_correction_term(self, frame: int) -> torch.Tensor:
        """The expression corrections' prior: squared, in units of PRIOR_EXPRESSION."""
        return (self.expression_correction(frame) / PRIOR_EXPRESSION).square().sum()
