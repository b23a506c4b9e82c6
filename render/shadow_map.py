"""A directional light's depth map of a mesh, looked up at any point in space: whether the mesh stands between
the point and the light. Pure tensor math over the map's arrays; the map itself is drawn by the GL rasterizer
(render/gl/shadow.py, draw_light_depth)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

LIGHT_MAP_PX = 256
"""Shadow-map size: 1.2 mm a texel over a 30 cm head."""
BIAS_M = 0.004
"""A point this far behind the nearest surface (seen from the light) still counts as lit: the surface's own
samples, within the shell's spacing of it, do not shadow themselves."""
SOFT_M = 0.004
"""Depth over which the test goes from lit to blocked (a smooth input for a network, not a hard step)."""


@dataclass
class LightDepthMap:
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

    def to(self, device: torch.device | str) -> LightDepthMap:
        return LightDepthMap(self.view.to(device), self.projection.to(device), self.depth.to(device))
