"""Per-frame codes for controls no training frame had (held-out frames, sliders, turntables).

The papers learn a code per training frame (NerFACE's and CoDyNeRF's latent codes) and leave open what a new
frame gets; the mean code is the usual answer. A tracked video's codes carry what the head model's controls do
not: where the hair fell, how the shoulders sat, the part of an expression the model misses; and those follow the
controls. So new controls take a blend of the codes of the training frames whose controls are nearest
(`nearest_code_weights`), and the codes change smoothly as the controls move.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import torch

from models.avatars.components.kept import Kept
from models.head.controls import Controls, fit_length

NEAREST_FRAMES = 5
"""Training frames whose codes a new frame blends. Chosen on the validation frames of the three shared clips (k
of 1, 3, 5, 10; README "Real people"), then kept for every capture."""
LEFT_OUT_WINDOW = 12
"""Frames each side of a training frame whose codes `left_out_weights` leaves out with it (half a second of
video: a held-out frame's nearest training frames are not its own moment)."""
KEY_SCALE_FLOOR = 0.01
"""The least spread (radians, or expression weight) a control's key is divided by: a control the training
frames never moved would otherwise blow any change of it up into a distance that outweighs all the rest."""


def frame_code(embedding: torch.nn.Embedding, frame: int | None, weights: torch.Tensor | None = None
               ) -> torch.Tensor:
    """(1,C) a training frame's code; for new controls (frame None) the training frames' codes blended by
    `weights` (N,) (nearest_code_weights), or without them their mean."""
    if frame is None:
        return embedding.weight.mean(0, keepdim=True) if weights is None else weights[None] @ embedding.weight
    return embedding(torch.tensor([frame], device=embedding.weight.device))


def control_key(controls: Controls, num_expression: int) -> np.ndarray:
    """(D,) what of a frame's controls its code may follow: rotations (root, neck, jaw, both eyes; radians) and
    expression weights. Not the translation or the shape: where the head stands and whose it is are the same in
    every frame of a capture."""
    return np.concatenate([controls.root, controls.neck, controls.jaw, controls.gaze_left, controls.gaze_right,
                           fit_length(controls.expression, num_expression, "expression")]).astype(np.float32)


def nearest_code_weights(keys: torch.Tensor, query: torch.Tensor, k: int = NEAREST_FRAMES) -> torch.Tensor:
    """(N,) weights summing to 1 over the training frames' keys (N,D) for a query (D,): the k nearest frames
    weighted by 1 - d_i / d_(k+1) (the distance to the first frame left out), so a weight reaches 0 just as its
    frame leaves the k nearest and the blend is continuous in the query. Where that leaves nothing (the k+1
    nearest all at one distance), the k nearest alike.

    Keys at 0, 1, 2, 4 and a query at 0.5 with k = 2: distances 0.5, 0.5, 1.5, 3.5; d_3 = 1.5; weights
    2/3, 2/3 -> 1/2 each.
    >>> nearest_code_weights(torch.tensor([[0.0], [1.0], [2.0], [4.0]]), torch.tensor([0.5]), 2)
    tensor([0.5000, 0.5000, 0.0000, 0.0000])
    >>> nearest_code_weights(torch.tensor([[0.0], [1.0], [2.0], [4.0]]), torch.tensor([0.25]), 2)  # 6/7 and 4/7
    tensor([0.6000, 0.4000, 0.0000, 0.0000])
    """
    assert keys.dim() == 2 and query.shape == keys.shape[1:], (keys.shape, query.shape)
    n = len(keys)
    d = (keys - query).norm(dim=-1)
    if n <= k:  # every frame is among the nearest: weighted by how near, against the farthest
        far = d.max()
        w = (1.0 - d / far) if far > 0 else torch.ones_like(d)
        return w / w.sum() if w.sum() > 0 else torch.full_like(d, 1.0 / n)
    dist, idx = torch.topk(d, k + 1, largest=False)
    w = torch.zeros_like(d)
    near = (1.0 - dist[:k] / dist[k]).clamp_min(0.0) if dist[k] > 0 else torch.zeros(k, dtype=d.dtype)
    near = near if near.sum() > 0 else torch.ones(k, dtype=d.dtype)
    w[idx[:k]] = near / near.sum()
    return w


def left_out_weights(keys: torch.Tensor, frame: int, window: int = LEFT_OUT_WINDOW, k: int = NEAREST_FRAMES
                     ) -> torch.Tensor:
    """(N,) the code weights a held-out frame with training frame `frame`'s key would get if that frame and the
    `window` frames each side of it (in the capture's order) were not in training: a training frame decoded with
    them asks the decoder what new controls ask of it.

    >>> left_out_weights(torch.tensor([[0.0], [1.0], [2.0], [4.0], [3.0]]), 1, window=1, k=1)
    tensor([0., 0., 0., 0., 1.])
    """
    n = len(keys)
    keep = (torch.arange(n, device=keys.device) - frame).abs() > window
    w = torch.zeros(n, dtype=keys.dtype, device=keys.device)
    if keep.any():
        w[keep] = nearest_code_weights(keys[keep], keys[frame], k)
    else:
        w[frame] = 1.0
    return w


class CodeKeys(Kept):
    """The training frames' control keys (N,D), divided by their spread (D,) (`scale`), that let new controls take
    the codes of the nearest training frames; none where the capture did not call for them (the mean code)."""

    weight_names: ClassVar[dict[str, str]] = {"keys": "code_keys", "scale": "code_key_scale"}

    def __init__(self, num_expression: int):
        super().__init__()
        self.num_expression = num_expression

    def note(self, controls: list[Controls], device: torch.device | str = "cpu") -> None:
        """Key the training frames' controls (in order; saved with the weights)."""
        keys = np.stack([control_key(c, self.num_expression) for c in controls])
        scale = np.maximum(keys.std(0), KEY_SCALE_FLOOR)
        self.keep("keys", torch.as_tensor(keys / scale, dtype=torch.float32, device=device))
        self.keep("scale", torch.as_tensor(scale, dtype=torch.float32, device=device))

    def weights(self, controls: Controls) -> torch.Tensor | None:
        """(N,) the training frames' share of the codes for these controls; None without keys (an older avatar,
        or a capture that did not call for them): the mean code."""
        if self.keys is None:
            return None
        query = torch.as_tensor(control_key(controls, self.num_expression), device=self.keys.device)
        return nearest_code_weights(self.keys, query / self.scale)
