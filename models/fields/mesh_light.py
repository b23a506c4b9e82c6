"""Whether the guide mesh stands between a point and the capture's key light: a shadow map of the posed mesh
(its depth seen from the light, drawn by the GL rasterizer), looked up at any point in space. The shadow
factor reads it beside its learnt inputs where the capture records its light, so the shadows it learns follow
the geometry that casts them, also where a region was in shadow in every training frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from render.gl.raster import Rasterizer
from render.gl.shadow import bounding_sphere, light_camera

LIGHT_MAP_PX = 256
"""Shadow-map size: 1.2 mm a texel over a 30 cm head."""
BIAS_M = 0.004
"""A point this far behind the nearest surface (seen from the light) still counts as lit: the surface's own
samples, within the shell's spacing of it, do not shadow themselves."""
SOFT_M = 0.004
"""Depth over which the test goes from lit to blocked (a smooth input for the network, not a hard step)."""


@dataclass
class MeshLight:
    view: torch.Tensor  # (4,4) world -> light camera
    projection: torch.Tensor  # (4,4) orthographic
    depth: torch.Tensor  # (N,N) distance from the light to the nearest surface, inf where none; rows top first

    def visibility(self, x: torch.Tensor) -> torch.Tensor:
        """(P,) in [0,1]: 1 where nothing of the mesh is between the point (P,3) and the light, 0 where it lies
        more than BIAS_M + SOFT_M behind the surface the light sees; bilinear between the four nearest texels
        (percentage-closer filtering). Points off the map, or not finite, count as lit."""
        finite = torch.isfinite(x).all(-1)
        x = torch.where(finite[:, None], x.detach(), torch.zeros_like(x)).clamp(-1e6, 1e6)
        h = torch.cat([x, torch.ones_like(x[:, :1])], 1)
        cam = h @ self.view.T
        ndc = cam @ self.projection.T
        n = self.depth.shape[0]
        u = (ndc[:, 0] + 1) * 0.5 * n - 0.5  # column, texel centres at integers
        v = (1 - ndc[:, 1]) * 0.5 * n - 0.5  # row, top first
        d = -cam[:, 2]
        u0, v0 = torch.floor(u), torch.floor(v)
        fu, fv = u - u0, v - v0
        out = torch.zeros_like(d)
        for du, dv, w in ((0, 0, (1 - fu) * (1 - fv)), (1, 0, fu * (1 - fv)), (0, 1, (1 - fu) * fv), (1, 1, fu * fv)):
            cu, cv = u0 + du, v0 + dv
            inside = (cu >= 0) & (cu < n) & (cv >= 0) & (cv < n)
            texel = self.depth[cv.clamp(0, n - 1).long(), cu.clamp(0, n - 1).long()]
            lit = ((texel + BIAS_M - d) / SOFT_M + 0.5).clamp(0, 1)
            out = out + w * torch.where(inside & torch.isfinite(texel), lit, torch.ones_like(lit))
        return torch.where(finite, out.clamp(0, 1), torch.ones_like(out))

    def to(self, device: torch.device | str) -> MeshLight:
        return MeshLight(self.view.to(device), self.projection.to(device), self.depth.to(device))


def mesh_light(vertices: np.ndarray, triangles: np.ndarray, light_dir: np.ndarray | tuple, rasterizer: Rasterizer,
               px: int = LIGHT_MAP_PX) -> MeshLight:
    """The shadow map of a posed mesh (V,3) for a directional light (towards the light, world)."""
    view, projection = light_camera(light_dir, *bounding_sphere(vertices))
    depth = rasterizer.depth_map(vertices, triangles, view, projection, px)
    t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)
    return MeshLight(t(view), t(projection), t(depth))
