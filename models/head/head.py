"""A head model made differentiable: controls in, posed vertices, joints and landmarks out."""

from __future__ import annotations

import numpy as np
import torch

from models.head.controls import Controls, ControlsError, fit_length
from models.head.lbs import lbs
from models.head.model import CONTROL_JOINTS, HeadModel


class Head(torch.nn.Module):
    """Posed meshes of one head model; stores no per-subject parameters.

    Joints the controls name but the model lacks (ICT has no neck or jaw joint) must be left at zero.
    """

    def __init__(self, model: HeadModel, dtype: torch.dtype = torch.float32):
        super().__init__()
        self.model = model
        self.parents = [int(p) for p in model.parents]

        def buf(name: str, array: np.ndarray) -> None:
            self.register_buffer(name, torch.as_tensor(np.asarray(array), dtype=dtype), persistent=False)

        buf("template", model.template)
        buf("shape_basis", model.shape_basis)
        buf("expr_basis", model.expr_basis)
        buf("pose_basis", model.pose_basis)
        buf("J_regressor", model.J_regressor)
        buf("weights", model.weights)
        ids, bary = model.landmarks.as_barycentric(model.triangles)
        self.register_buffer("lmk_ids", torch.as_tensor(ids), persistent=False)
        buf("lmk_bary", bary)
        # Control joint k drives model joint joint_index[k] (or nothing if the model lacks it).
        self.joint_index = {name: model.joint_names.index(name) for name in CONTROL_JOINTS
                            if name in model.joint_names}

    def full_pose(self, controls: list[Controls]) -> torch.Tensor:
        """(B,J,3) axis-angle per model joint from the controls' named rotations."""
        pose = np.zeros((len(controls), self.model.num_joints, 3), np.float32)
        for b, c in enumerate(controls):
            for name in CONTROL_JOINTS:
                rot = c.rotation(name)
                if name in self.joint_index:
                    pose[b, self.joint_index[name]] = rot
                elif np.any(rot != 0):
                    raise ControlsError(
                        f"head model '{self.model.name}' has no '{name}' joint; leave that rotation at zero"
                    )
        return torch.as_tensor(pose, dtype=self.template.dtype, device=self.template.device)

    def batch(self, controls: list[Controls]) -> dict[str, torch.Tensor]:
        """Tensors for forward(): shape (B,S), expression (B,E), full_pose (B,J,3), translation (B,3)."""
        m = self.model
        as_t = lambda a: torch.as_tensor(np.stack(a), dtype=self.template.dtype, device=self.template.device)
        return {
            "shape": as_t([fit_length(c.shape, m.num_shape, "shape") for c in controls]),
            "expression": as_t([fit_length(c.expression, m.num_expression, "expression") for c in controls]),
            "full_pose": self.full_pose(controls),
            "translation": as_t([np.asarray(c.translation, np.float32) for c in controls]),
        }

    def forward(
        self,
        shape: torch.Tensor,  # (B,S)
        expression: torch.Tensor,  # (B,E)
        full_pose: torch.Tensor,  # (B,J,3)
        translation: torch.Tensor,  # (B,3)
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """vertices (B,V,3), joints (B,J,3), landmarks (B,L,3), all in metres."""
        verts, joints = lbs(shape, expression, full_pose, self.template, self.shape_basis,
                            self.expr_basis, self.pose_basis, self.J_regressor, self.parents, self.weights)
        verts = verts + translation[:, None]
        joints = joints + translation[:, None]
        lmks = (verts[:, self.lmk_ids] * self.lmk_bary[None, ..., None]).sum(2)
        return verts, joints, lmks

    def pose(self, controls: Controls | list[Controls]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """forward() on controls; a single Controls gives a batch of one."""
        controls = [controls] if isinstance(controls, Controls) else controls
        return self(**self.batch(controls))


def posed_mesh(head: Head, controls: Controls) -> tuple[np.ndarray, np.ndarray]:
    """Posed vertices (V,3) and landmarks (L,3) as numpy, for drawing and writing files."""
    with torch.inference_mode():
        verts, _, lmks = head.pose(controls)
    return verts[0].numpy(), lmks[0].numpy()
