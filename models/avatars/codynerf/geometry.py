"""One frame's head as CoDyNeRF's rays need it (docs/models.md): the canonical, expressed and posed meshes
for the 3DMM prior, a k-d tree for nearest-vertex queries, the landmarks the appearance reads, the head's box,
and, for avatars whose shadow factor reads it, the posed mesh's depth map from the key light."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch
from pykdtree.kdtree import KDTree

from models.avatars.codynerf.prior import PriorMeshes, vertex_tree
from models.head.controls import Controls
from models.head.head import Head
from render.gl.raster import Rasterizer
from render.gl.shadow import draw_light_depth
from render.mesh import vertex_normals
from render.shadow_map import LightDepthMap


@dataclass
class FrameGeometry:
    """Everything about one frame's head that the rays need: meshes, k-d tree, landmarks, box."""

    meshes: PriorMeshes
    tree: KDTree
    landmarks: torch.Tensor  # (1, 3L) relative to the landmarks' centre
    box_min: torch.Tensor  # (3,)
    box_max: torch.Tensor  # (3,)
    neutral_landmarks: torch.Tensor  # (1, 3L) the same for the neutral head (no expression, no pose): inspection
    light: LightDepthMap | None = None  # the posed mesh seen from the key light, where the shadow factor reads it
    code_weights: torch.Tensor | None = None  # (N,) the training frames' share of new controls' codes (None: mean)

    @property
    def posed(self) -> torch.Tensor:
        """(V,3) the posed mesh, world."""
        return self.meshes.posed

    def to(self, device: torch.device | str) -> FrameGeometry:
        """The same geometry with its tensors on `device` (the k-d tree stays on the CPU)."""
        m = self.meshes
        return FrameGeometry(PriorMeshes(*(t.to(device) for t in (m.canonical, m.expressed, m.posed, m.normals))),
                             self.tree, self.landmarks.to(device), self.box_min.to(device), self.box_max.to(device),
                             self.neutral_landmarks.to(device), None if self.light is None else self.light.to(device),
                             None if self.code_weights is None else self.code_weights.to(device))


@torch.no_grad()
def frame_geometry(head: Head, controls: Controls, box_margin_m: float) -> FrameGeometry:
    """The frame's canonical (identity only), expressed and posed meshes, their tree, landmarks and box."""
    neutral = Controls(shape=controls.shape)
    unposed = Controls(shape=controls.shape, expression=controls.expression)
    v, _, lm = head.pose([neutral, unposed, controls])
    posed = v[2]
    normals = torch.as_tensor(vertex_normals(posed.cpu().numpy(), head.model.triangles)).to(posed.device)
    centred = lambda p: (p - p.mean(0) if lm.shape[1] else torch.zeros(1, 3, device=posed.device)).reshape(1, -1)
    return FrameGeometry(PriorMeshes(v[0], v[1], posed, normals), vertex_tree(posed), centred(lm[2]),
                         posed.min(0).values - box_margin_m, posed.max(0).values + box_margin_m, centred(lm[0]))


def with_light_depth(geo: FrameGeometry, triangles: np.ndarray, light_dir: tuple[float, float, float],
                     rasterizer: Rasterizer) -> FrameGeometry:
    """The geometry with the posed mesh's depth map from the key light (drawn by the GL rasterizer)."""
    light = draw_light_depth(rasterizer, geo.posed.cpu().numpy(), triangles, light_dir)
    return replace(geo, light=light.to(geo.posed.device))
