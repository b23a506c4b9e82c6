"""The 3DMM deformation prior (CoDyNeRF, Eq. 3-4; RigNeRF): each sample is pulled towards canonical space
by the deformation of its nearest point on the posed head mesh, weakened with distance from the mesh.

    x_hat = argmin_{v in posed mesh} |x - v|,   DistToMesh(x) = |x - x_hat|
    prior(x) = (canonical(x_hat) - posed(x_hat)) * exp(-DistToMesh(x) / falloff)

The paper divides by exp(DistToMesh); with distances in metres a length scale `falloff_m` sets how far
the prior reaches (exp(-d / falloff) never overflows, so points 10 m or 1e6 m away get a prior of zero, not
an inf or a nan). The deformation splits into an expression part (neutral -> expression, before pose) and a
pose part (-> posed), the separate inputs of the dynamic appearance (Eq. 7).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
from pykdtree.kdtree import KDTree


@dataclass(frozen=True)
class PriorMeshes:
    """One frame's head meshes, vertex for vertex: canonical (identity only), expression applied, posed."""

    canonical: torch.Tensor  # (V,3)
    expressed: torch.Tensor  # (V,3) identity + expression, not posed
    posed: torch.Tensor  # (V,3) world space
    normals: torch.Tensor  # (V,3) unit vertex normals of the posed mesh


@dataclass(frozen=True)
class PriorSamples:
    """The prior at a batch of sample points (P points)."""

    nearest: torch.Tensor  # (P,) vertex index of x_hat
    distance: torch.Tensor  # (P,) DistToMesh, metres
    offset: torch.Tensor  # (P,3) prior deformation towards canonical space (Eq. 4), metres
    expression_offset: torch.Tensor  # (P,3) its expression-only part
    pose_offset: torch.Tensor  # (P,3) its pose-only part
    mesh_normal: torch.Tensor  # (P,3) posed normal at x_hat

    def take(self, idx: torch.Tensor) -> PriorSamples:
        """The prior at a subset of the points (indices)."""
        return PriorSamples(*(getattr(self, f.name)[idx] for f in fields(self)))


def vertex_tree(vertices: torch.Tensor) -> KDTree:
    """A k-d tree over (V,3) vertices, to reuse for every sample of one frame. pykdtree queries in float32
    with OpenMP, 2.2x faster than scipy's cKDTree here (97k points, 17k vertices: 81 ms vs 175 ms), and the
    nearest vertex is the same for all but 3 points in 100,000 (ties within float32 rounding)."""
    return KDTree(np.ascontiguousarray(vertices.detach().cpu().numpy(), np.float32))


def nearest_vertices(points: torch.Tensor, vertices: torch.Tensor, tree: KDTree | None = None) -> torch.Tensor:
    """(P,) index of the nearest vertex of (V,3) `vertices` to each of (P,3) `points` (a k-d tree; no
    gradient flows through the choice)."""
    tree = tree if tree is not None else vertex_tree(vertices)
    pts = points.detach().cpu().numpy().astype(np.float32)
    # Far points (10 m, 1e6 m) keep a valid nearest vertex; non-finite ones are queried at the origin.
    pts = np.where(np.isfinite(pts), pts, np.float32(0.0))
    _, idx = tree.query(pts, k=1)
    return torch.as_tensor(idx.astype(np.int64), device=points.device)


def deformation_prior(points: torch.Tensor, meshes: PriorMeshes, falloff_m: float = 0.05,
                      tree: KDTree | None = None) -> PriorSamples:
    """The prior (Eq. 3-4) at (P,3) world points; differentiable in the points and the meshes. `tree`:
    a prebuilt vertex_tree of meshes.posed."""
    assert points.ndim == 2 and points.shape[1] == 3, f"points must be (P,3), got {tuple(points.shape)}"
    return prior_at(points, nearest_vertices(points, meshes.posed, tree), meshes, falloff_m)


def prior_within(points: torch.Tensor, meshes: PriorMeshes, reach_m: float, falloff_m: float = 0.05,
                 tree: KDTree | None = None) -> tuple[torch.Tensor, PriorSamples]:
    """The prior only at those of the (P,3) points nearer the mesh than reach_m: their indices and the prior
    there (the others are never computed)."""
    idx = nearest_vertices(points, meshes.posed, tree)
    which = torch.nonzero((points - meshes.posed[idx]).norm(dim=-1) < reach_m).squeeze(1)
    return which, prior_at(points[which], idx[which], meshes, falloff_m)


def prior_at(points: torch.Tensor, idx: torch.Tensor, meshes: PriorMeshes, falloff_m: float) -> PriorSamples:
    """The prior at (P,3) points whose nearest posed vertices are idx (P,)."""
    x_hat = meshes.posed[idx]
    diff = points - x_hat
    # |diff| with a gradient that stays finite where a point sits exactly on a vertex.
    distance = torch.sqrt((diff * diff).sum(-1) + 1e-18)
    decay = torch.exp(-distance / falloff_m)[:, None]
    expression = (meshes.canonical[idx] - meshes.expressed[idx]) * decay
    pose = (meshes.expressed[idx] - x_hat) * decay
    return PriorSamples(idx, distance, expression + pose, expression, pose, meshes.normals[idx])
