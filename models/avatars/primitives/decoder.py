"""The primitives' decoder (MVP, Lombardi et al. 2021; Cao et al. 2022, Section 3.1.1 and Fig. 3): once per frame, the
frame's condition (expression and pose from the head model's controls, a per-frame code, the view direction)
becomes a 4x4 feature map, upsampled by transposed convolutions with LeakyReLU to the slab image: K M x K M pixels
whose channels are the M depth layers of opacity (and of colour, 3 M) of the K x K grid's primitives, one M x M
tile each. Gaze enters apart from expression, concatenated to the features at the 8x8 level (the seed's
disentangled gaze). Every upsampling level adds a learnt, untied bias map (the seed's bias maps; the prior of the
next issue generates them per identity). At the K x K level a 1x1 convolution gives each primitive's offsets: a
move, a turn and a log-scale, zero at the start so that the primitives begin where the layout puts them.

Maps in the slab's own layout (one channel per input, K M x K M: the key light's visibility of each primitive's
texels where the capture casts shadows) join the last upsampling (averaged to its size) and the slab's
convolution, so what a texel decodes follows what the light sees there. Geometry maps in the same layout (the
frame's expression as the guide mesh shows it, avatar.py `expression_maps`) join earlier, every upsampling from
the K x K level on (averaged to each one's size) and the slab's convolution: what a primitive decodes then follows
how the mesh moved where it sits, not only the global condition."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn


class SlabDecoder(nn.Module):
    def __init__(self, condition_dim: int, gaze_dim: int, grid: int, voxels: int, colour_channels: int = 3,
                 width: int = 64, min_width: int = 16, map_channels: int = 0, latent_channels: int = 0,
                 geometry_channels: int = 0, code_channels: int = 0):
        """latent_channels > 0: the frame's expression is a spatial 4x4 code of that many channels (the prior's,
        Cao et al. 2022 Section 3.1.1), joined by the condition vector (view, light) at every cell through a 1x1
        convolution, instead of the condition vector alone through a linear layer. code_channels > 0: the per-frame
        code joins apart from the condition, at the K x K level, weighted by a mask (forward's code_mask)."""
        super().__init__()
        assert grid >= 8 and grid & (grid - 1) == 0 and voxels & (voxels - 1) == 0, (grid, voxels)
        self.grid, self.voxels, self.colour_channels, self.gaze_dim = grid, voxels, colour_channels, gaze_dim
        self.map_channels, self.latent_channels = map_channels, latent_channels
        self.geometry_channels, self.code_channels = geometry_channels, code_channels
        self.fc = nn.Linear(condition_dim, 16 * width) if not latent_channels else \
            nn.Conv2d(latent_channels + condition_dim, width, 1)
        self.width = width
        levels = int(math.log2(grid * voxels // 4))
        self.offset_level = int(math.log2(grid // 4)) - 1  # the upsampling after which the map is K x K
        chans = [width]
        for k in range(levels):
            chans.append(max(min_width, width // (2 ** max(0, k - 1))))
        self.ups = nn.ModuleList()
        self.biases = nn.ParameterList()
        for k in range(levels):
            c_in = chans[k] + (gaze_dim if k == 1 else 0)  # gaze joins at 8x8 (after the first upsampling)
            c_in += map_channels if k == levels - 1 else 0  # the maps, halved, join the last upsampling
            c_in += geometry_channels if k > self.offset_level else 0  # geometry from the K x K level on
            c_in += code_channels if k == self.offset_level + 1 else 0  # the masked code at K x K
            self.ups.append(nn.ConvTranspose2d(c_in, chans[k + 1], 4, stride=2, padding=1))
            size = 4 * 2 ** (k + 1)
            self.biases.append(nn.Parameter(torch.zeros(chans[k + 1], size, size)))
        self.out_channels = voxels * (1 + colour_channels)
        self.slab = nn.Conv2d(chans[-1] + map_channels + geometry_channels, self.out_channels, 3, padding=1)
        self.slab_bias = nn.Parameter(torch.zeros(self.out_channels, grid * voxels, grid * voxels))
        self.offsets = nn.Conv2d(chans[self.offset_level + 1], 9, 1)
        nn.init.zeros_(self.offsets.weight)
        nn.init.zeros_(self.offsets.bias)

    def bias_shapes(self) -> list[tuple[int, int, int]]:
        """(C,H,W) of the bias map after each upsampling, then of the slab's: what the prior's identity encoder
        writes (forward's bias_maps)."""
        return [tuple(b.shape) for b in self.biases] + [tuple(self.slab_bias.shape)]

    def forward(self, condition: torch.Tensor, gaze: torch.Tensor, maps: torch.Tensor | None = None,
                latent: torch.Tensor | None = None, bias_maps: list[torch.Tensor] | None = None,
                gaze_mask: torch.Tensor | None = None, geometry: torch.Tensor | None = None,
                code: torch.Tensor | None = None, code_mask: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """condition (1,Dc), gaze (1,Dg), maps (1, map_channels, K M, K M) -> raw opacity (K*K, M,M,M), raw colour
        (K*K, M,M,M, C) and offsets (K*K, 9), primitives in row-major grid order, voxels [z, y, x].
        latent (1, latent_channels, 4, 4): the spatial expression code, where the decoder takes one; bias_maps
        (bias_shapes, each with a leading 1): added to the decoder's own biases (an identity's, from the prior);
        gaze_mask (1,1,8,8): where on the 8x8 features gaze may act (1 everywhere if not given); geometry
        (1, geometry_channels, K M, K M): the geometry maps, where the decoder takes them; code (1, code_channels)
        and code_mask (1,1,K,K): the per-frame code and where on the K x K features it may act."""
        assert (maps is None) == (self.map_channels == 0), "maps go with map_channels"
        assert (geometry is None) == (self.geometry_channels == 0), "geometry maps go with geometry_channels"
        assert (latent is None) == (self.latent_channels == 0), "a latent goes with latent_channels"
        assert (code is None) == (self.code_channels == 0), "a code apart goes with code_channels"
        K, M, C = self.grid, self.voxels, self.colour_channels
        if latent is None:
            h = F.leaky_relu(self.fc(condition).reshape(1, self.width, 4, 4), 0.2)
        else:
            h = F.leaky_relu(self.fc(torch.cat([latent, condition[:, :, None, None].expand(-1, -1, 4, 4)], 1)), 0.2)
        extra = bias_maps or [0.0] * (len(self.biases) + 1)
        offsets = None
        for k, (up, bias) in enumerate(zip(self.ups, self.biases, strict=True)):
            if k == 1:
                g = gaze[:, :, None, None].expand(-1, -1, h.shape[2], h.shape[3])
                h = torch.cat([h, g if gaze_mask is None else g * gaze_mask], 1)
            if maps is not None and k == len(self.ups) - 1:
                h = torch.cat([h, F.avg_pool2d(maps, 2)], 1)
            if geometry is not None and k > self.offset_level:
                h = torch.cat([h, F.adaptive_avg_pool2d(geometry, h.shape[2:])], 1)
            if code is not None and k == self.offset_level + 1:
                c = code[:, :, None, None].expand(-1, -1, h.shape[2], h.shape[3])
                h = torch.cat([h, c if code_mask is None else c * code_mask], 1)
            h = F.leaky_relu(up(h) + bias[None] + extra[k], 0.2)
            if k == self.offset_level:
                offsets = self.offsets(h)
        joined = [h] + [m for m in (maps, geometry) if m is not None]
        slab = self.slab(torch.cat(joined, 1) if len(joined) > 1 else h) + self.slab_bias[None] + extra[-1]
        slab = slab.reshape(1 + C, M, K, M, K, M)  # channel (c, z), rows (i, y), columns (j, x)
        slab = slab.permute(2, 4, 0, 1, 3, 5).reshape(K * K, 1 + C, M, M, M)  # (prim, c, z, y, x)
        offsets = offsets[0].permute(1, 2, 0).reshape(K * K, 9)
        return slab[:, 0], slab[:, 1:].permute(0, 2, 3, 4, 1), offsets
