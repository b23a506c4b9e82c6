"""Linear blend skinning with shape, expression and pose-corrective blend shapes, as pure functions.

Follows FLAME/SMPL: v_shaped = T + B_S(beta) + B_E(psi); J = J_regressor v_shaped;
v_posed = v_shaped + B_P(theta); v = sum_j w_j G_j(theta, J) v_posed.
"""

from __future__ import annotations

import torch

#: Below this angle (radians) the rotation uses a Taylor expansion of Rodrigues' formula.
_SMALL_ANGLE = 1e-4


def rotation_matrix_from_axis_angle(rot_vecs: torch.Tensor) -> torch.Tensor:
    """Rodrigues: R = I + sin(t)/t K + (1-cos(t))/t^2 K^2 for axis-angle r with t = |r|, K = [r]_x.

    rot_vecs: (..., 3) radians. Returns (..., 3, 3). Finite, with finite gradients, at t = 0 (the
    coefficients switch to their Taylor series there, 1 - t^2/6 and 1/2 - t^2/24) and at t = pi, 2 pi.

    >>> R = rotation_matrix_from_axis_angle(torch.tensor([0.0, 0.0, torch.pi / 2], dtype=torch.float64))
    >>> (R @ torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)).round(decimals=12)  # +x turns to +y
    tensor([0., 1., 0.], dtype=torch.float64)
    """
    theta2 = (rot_vecs * rot_vecs).sum(-1, keepdim=True)  # (...,1)
    small = theta2 < _SMALL_ANGLE**2
    theta2_safe = torch.where(small, torch.ones_like(theta2), theta2)
    theta = theta2_safe.sqrt()
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta2_safe)
    x, y, z = rot_vecs.unbind(-1)
    zero = torch.zeros_like(x)
    K = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(*rot_vecs.shape[:-1], 3, 3)
    eye = torch.eye(3, dtype=rot_vecs.dtype, device=rot_vecs.device).expand_as(K)
    return eye + a[..., None] * K + b[..., None] * (K @ K)


def blend_shapes(coeffs: torch.Tensor, basis: torch.Tensor) -> torch.Tensor:
    """Offsets sum_k coeffs[b,k] basis[v,c,k]. coeffs: (B,K), basis: (V,3,K) -> (B,V,3)."""
    if basis.shape[2] == 0:
        return torch.zeros(coeffs.shape[0], basis.shape[0], 3, dtype=basis.dtype, device=basis.device)
    return torch.einsum("bk,vck->bvc", coeffs, basis)


def rigid_transforms(
    rot_mats: torch.Tensor,  # (B,J,3,3) local rotations
    joints: torch.Tensor,  # (B,J,3) rest joint positions
    parents: list[int],  # (J,)
) -> tuple[torch.Tensor, torch.Tensor]:
    """World transforms of a joint chain, relative to the rest pose.

    G_j = G_parent(j) [R_j | J_j - J_parent(j)]; returns the posed joints (B,J,3) and
    A_j = G_j with the rest-pose joint position removed, (B,J,4,4), so that v = A_j [v_rest; 1].
    """
    B, J = joints.shape[:2]
    rel = joints.clone()
    rel[:, 1:] = joints[:, 1:] - joints[:, parents[1:]]
    local = torch.zeros(B, J, 4, 4, dtype=joints.dtype, device=joints.device)
    local[..., :3, :3] = rot_mats
    local[..., :3, 3] = rel
    local[..., 3, 3] = 1.0
    chain = [local[:, 0]]
    for j in range(1, J):
        chain.append(chain[parents[j]] @ local[:, j])
    world = torch.stack(chain, dim=1)  # (B,J,4,4)
    posed_joints = world[..., :3, 3]
    # Remove the rest position: A_j = G_j - [0 | G_j J_j].
    shift = (world[..., :3, :3] @ joints[..., None])[..., 0]
    A = world.clone()
    A[..., :3, 3] = world[..., :3, 3] - shift
    return posed_joints, A


def lbs(
    shape: torch.Tensor,  # (B,S)
    expression: torch.Tensor,  # (B,E)
    full_pose: torch.Tensor,  # (B,J,3) axis-angle per joint, radians
    template: torch.Tensor,  # (V,3)
    shape_basis: torch.Tensor,  # (V,3,S)
    expr_basis: torch.Tensor,  # (V,3,E)
    pose_basis: torch.Tensor,  # (V,3,(J-1)*9) or (V,3,0)
    J_regressor: torch.Tensor,  # (J,V)
    parents: list[int],  # (J,)
    weights: torch.Tensor,  # (V,J)
    rest_joints: torch.Tensor | None = None,  # (B,J,3): given, J_regressor is not used
) -> tuple[torch.Tensor, torch.Tensor]:
    """Posed vertices (B,V,3) and joints (B,J,3), FLAME's forward pass without translation. With rest_joints
    (computed from the whole mesh), the vertices may be any subset of the model's."""
    B = shape.shape[0]
    _V, J = weights.shape
    assert full_pose.shape == (B, J, 3), f"full_pose must be (B,J,3)=({B},{J},3), got {full_pose.shape}"
    assert expression.shape[0] == B, "shape and expression batch sizes differ"
    # 1. Identity and expression blend shapes.
    v_shaped = template[None] + blend_shapes(shape, shape_basis) + blend_shapes(expression, expr_basis)
    # 2. Rest joints from the shaped mesh.
    joints = torch.einsum("jv,bvc->bjc", J_regressor, v_shaped) if rest_joints is None else rest_joints
    # 3. Pose correctives from (R - I) of every joint but the root.
    rot_mats = rotation_matrix_from_axis_angle(full_pose)  # (B,J,3,3)
    v_posed = v_shaped
    if pose_basis.shape[2] > 0:
        eye = torch.eye(3, dtype=rot_mats.dtype, device=rot_mats.device)
        pose_feature = (rot_mats[:, 1:] - eye).reshape(B, -1)
        v_posed = v_shaped + blend_shapes(pose_feature, pose_basis)
    # 4. Skinning.
    posed_joints, A = rigid_transforms(rot_mats, joints, parents)
    T = torch.einsum("vj,bjrc->bvrc", weights, A)  # (B,V,4,4)
    verts = (T[..., :3, :3] @ v_posed[..., None])[..., 0] + T[..., :3, 3]
    return verts, posed_joints
