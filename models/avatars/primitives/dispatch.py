"""Which march runs, chosen in one place and reported: the pure-torch reference (march.py) or the C code (native.py).

Training marches in torch, every candidate in one pass with gradients; its trilinear lookups run in C where the grids
are float32 on the CPU (the 3D grid_sample's forward and backward took a quarter of a training step's CPU time),
else by grid_sample. Display marches in C where it can (CPU tensors, no gradient, at most native.MAX_CHANNELS
colour channels: 3x faster on one core), else in torch (march_in_parts, its lookups chosen as training's are). Each
call says which ran, and why torch where the C code was passed over (`native.unavailable`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import torch

from models.avatars.primitives import march, native


@dataclass(frozen=True)
class Display:
    """Display's march: waves with early termination, samples by the voxels a segment crosses, colour looked up only
    where a sample shows (march.DISPLAY_MIN_WEIGHT)."""

    stop_below: float
    """A ray takes no more samples once less than this share of its light gets through."""
    parts: int = 1
    """Groups of rays, each on a thread of its own (march_in_parts; the C march deals its rays alike)."""
    should_stop: Callable[[], bool] | None = None
    """Asked between waves (torch) or calls (C); yes raises RenderCancelled."""


@dataclass(frozen=True)
class Ran:
    """What marched: the march itself and its trilinear lookups, each "c" or "torch", and why torch where the C code
    was passed over ("" where C ran or torch was the only choice)."""

    march: Literal["c", "torch"]
    lookups: Literal["c", "torch"]
    why: str = ""

    def __str__(self) -> str:
        """As the studio's quality panel names display's march.

        >>> str(Ran("c", "c")), str(Ran("torch", "torch", "AVATAR_STUDIO_NATIVE=0"))
        ('C', 'torch (AVATAR_STUDIO_NATIVE=0)')
        """
        return "C" if self.march == "c" else f"torch ({self.why})" if self.why else "torch"


def march_rays(origins: torch.Tensor, directions: torch.Tensor, background: torch.Tensor, prims: march.Primitives,
               samples: int, display: Display | None = None,
               band: tuple[torch.Tensor, torch.Tensor] | None = None) -> tuple[march.MarchOutput, Ran]:
    """R rays (origins, directions (R,3), background (R,3) or (3,)) marched through the primitives, `samples`
    samples a segment at most: for training (display None: one pass, every candidate, gradients; band: march's) or
    for display; and which code ran."""
    lookups_why = native.unavailable(prims, origins, display=False)
    gather = native.trilinear if not lookups_why else None
    lookups = "torch" if lookups_why else "c"
    if display is None:
        lists = march.candidate_lists(origins, directions, prims)
        return march.march(origins, directions, background, prims, lists, samples, gather=gather, band=band), \
            Ran("torch", lookups, lookups_why)
    march_why = native.unavailable(prims, origins, display=True)
    if not march_why:
        lists = march.candidate_lists(origins, directions, prims)
        return native.march(origins, directions, background, prims, lists, samples, display.stop_below,
                            march.DISPLAY_MIN_WEIGHT, display.parts, should_stop=display.should_stop), \
            Ran("c", "c")
    out = march.march_in_parts(origins, directions, background, prims, samples, display.stop_below, display.parts,
                               gather=gather, min_weight=march.DISPLAY_MIN_WEIGHT, adaptive=True,
                               should_stop=display.should_stop)
    return out, Ran("torch", lookups, march_why)
