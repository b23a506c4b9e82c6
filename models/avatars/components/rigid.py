"""The head's rigid motion in a frame: how models that read a frame in the head's own frame (NerFACE, the primitives'
view direction) get the head's pose from the posed mesh and joints, whatever the head model's joints."""

from __future__ import annotations

import numpy as np
import torch

from models.head.controls import Controls
from models.head.lbs import rotation_matrix_from_axis_angle
from models.head.model import HeadModel


def kabsch(source: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The rotation R and translation t minimising |R source + t - target| over (V,3) point sets."""
    cs, ct = source.mean(0), target.mean(0)
    u, _, vh = torch.linalg.svd((source - cs).T.double() @ (target - ct).double())
    d = torch.sign(torch.linalg.det(vh.T @ u.T))
    r = (vh.T @ torch.diag(torch.tensor([1.0, 1.0, float(d)], dtype=torch.float64, device=vh.device)) @ u.T).float()
    return r, ct - r @ cs


def head_pose(head_model: HeadModel, controls: Controls, vertices: torch.Tensor, joints: torch.Tensor
              ) -> tuple[torch.Tensor, torch.Tensor]:
    """The head's rigid motion R, t from its rest (vertices[0], joints[0]: the controls without any turn) to the
    frame (vertices[1], joints[1]). Where the neck turned (a tracked video keeps the body still and turns the head on
    it: models/tracking/torso.py), exactly the head's own turn (Controls.head_rotation) about the neck joint and
    where that joint went: a fit to the whole mesh would take in the still shoulders. Else the best rigid motion of
    the whole mesh (kabsch), as avatars trained before the neck turned were."""
    if not turned_on_body(head_model, controls):
        return kabsch(vertices[0], vertices[1])
    neck = head_model.joint_names.index("neck")
    rotation = head_turn(controls).to(vertices)
    return rotation, joints[1, neck] - rotation @ joints[0, neck]


def turned_on_body(head_model: HeadModel, controls: Controls) -> bool:
    """Whether the controls turn the head on a still body (a neck joint, turned): the head's own frame is then not
    the whole mesh's."""
    return "neck" in head_model.joint_names and bool(np.any(controls.neck))


def head_turn(controls: Controls) -> torch.Tensor:
    """(3,3) the rotation of the controls' head: the root's and the neck's turns composed (Controls.head_rotation)."""
    return rotation_matrix_from_axis_angle(torch.as_tensor(controls.head_rotation())[None])[0]
