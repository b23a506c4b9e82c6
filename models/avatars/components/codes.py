"""Per-frame codes for controls no training frame had (held-out frames, sliders, turntables).

The papers learn a code per training frame (NerFACE's and CoDyNeRF's latent codes) and leave open what a new
frame gets; the mean code is the usual answer. A tracked video's codes carry what the head model's controls do
not: where the hair fell, how the shoulders sat, the part of an expression the model misses; and those follow the
controls. So new controls take a blend of the codes of the training frames whose controls are nearest
(`nearest_code_weights`), and the codes change smoothly as the controls move.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
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
TIME_SCALE_S = 0.1
"""Seconds of a video that weigh as much as one spread of a control in a code key with a time: a frame 0.1 s
away is as far as one whose controls differ by a spread, so near frames decide unless the controls differ a lot.
On seven 10-minute avatars (28 November, held-out frames): +0.4 to +2.9 dB on five clips, 0 on one, -2.0 dB on
the expressions clip d19, whose codes follow its expressions; hence the choice per capture."""
FORECAST_GAP_S = 0.3
"""The choice's validation frames blend only the codes of training frames filmed this much earlier or more:
as a held-out frame after the training frames gets them (its moment is not among them)."""
KEY_SCALE_FLOOR = 0.01
"""The least spread (radians, or expression weight) a control's key is divided by: a control the training
frames never moved would otherwise blow any change of it up into a distance that outweighs all the rest."""


GAZE_KEYS = slice(9, 15)
"""The eyes' rotations (left, then right) in a control_key: after the root's, the neck's and the jaw's, three each."""


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

    weight_names: ClassVar[dict[str, str]] = {"keys": "code_keys", "scale": "code_key_scale",
                                              "times": "code_key_times", "time_scale": "code_time_scale"}

    def __init__(self, num_expression: int):
        super().__init__()
        self.num_expression = num_expression
        self._forecasting = False  # within `forecasting`, keyed by time at _forecast_scale (None: by controls)
        self._forecast_scale: float | None = None

    def note(self, controls: list[Controls], times: list[float | None] | None = None,
             device: torch.device | str = "cpu") -> None:
        """Key the training frames' controls (in order; saved with the weights), and their times in the video
        (seconds) where every frame has one."""
        keys = np.stack([control_key(c, self.num_expression) for c in controls])
        scale = np.maximum(keys.std(0), KEY_SCALE_FLOOR)
        self.keep("keys", torch.as_tensor(keys / scale, dtype=torch.float32, device=device))
        self.keep("scale", torch.as_tensor(scale, dtype=torch.float32, device=device))
        if times is not None and len(times) == len(controls) and all(t is not None for t in times):
            self.keep("times", torch.as_tensor(times, dtype=torch.float32, device=device))

    @property
    def keys_time(self) -> bool:
        """Whether frames with a time take the codes nearest in controls and time (training chose it)."""
        return self.times is not None and self.time_scale is not None

    def choose_time(self, scale: float | None) -> None:
        """Key frames with a time by controls and time, a second weighing as 1/scale spreads (None: by controls)."""
        if scale is None:
            self.register_buffer("time_scale", None)
        else:
            self.keep("time_scale", torch.tensor(float(scale), device=self.keys.device))

    def trained_range(self, columns: slice) -> tuple[np.ndarray, np.ndarray] | None:
        """The least and the most the training frames' controls took in these columns of their keys (control_key's
        units: radians, expression weights); None without keys.

        >>> k = CodeKeys(0)
        >>> k.note([Controls(root=np.array([0.1, 0.0, 0.0])), Controls(root=np.array([0.3, 0.0, 0.0]))])
        >>> [[round(float(x), 3) for x in v] for v in k.trained_range(slice(0, 3))]
        [[0.1, 0.0, 0.0], [0.3, 0.0, 0.0]]
        """
        if self.keys is None:
            return None
        raw = (self.keys[:, columns] * self.scale[columns]).cpu().numpy()
        return raw.min(0), raw.max(0)

    def weights(self, controls: Controls, time_s: float | None = None) -> torch.Tensor | None:
        """(N,) the training frames' share of the codes for these controls; None without keys (an older avatar,
        or a capture that did not call for them): the mean code. time_s: the time in the capture's video of a
        frame of it (a held-out frame): keyed by time as well where training chose it."""
        if self.keys is None:
            return None
        query = torch.as_tensor(control_key(controls, self.num_expression), device=self.keys.device) / self.scale
        keys = self.keys
        if self._forecasting:
            scale = self._forecast_scale
        else:
            scale = float(self.time_scale) if self.time_scale is not None else None
        if time_s is not None and self.times is not None and scale is not None:
            keys = torch.cat([keys, (self.times / scale)[:, None]], 1)
            query = torch.cat([query, query.new_tensor([time_s / scale])])
        if not self._forecasting or time_s is None or self.times is None:
            return nearest_code_weights(keys, query)
        earlier = self._filmed_before(time_s)
        w = torch.zeros(len(keys), dtype=keys.dtype, device=keys.device)
        w[earlier] = nearest_code_weights(keys[earlier], query)
        return w

    def forecastable(self, time_s: float) -> bool:
        """Whether enough training frames were filmed FORECAST_GAP_S before this time for `forecasting` to blend."""
        return self.times is not None and int(self._filmed_before(time_s).sum()) > NEAREST_FRAMES

    def _filmed_before(self, time_s: float) -> torch.Tensor:
        """(N,) bool: the training frames filmed FORECAST_GAP_S or more before this time."""
        return self.times < time_s - FORECAST_GAP_S

    @contextlib.contextmanager
    def forecasting(self, scale: float | None) -> Iterator[None]:
        """Within: frames with a time blend only the codes of training frames filmed FORECAST_GAP_S or more
        before them (as a held-out frame after them would), keyed by time at `scale` (None: by controls alone)."""
        self._forecasting, self._forecast_scale = True, scale
        try:
            yield
        finally:
            self._forecasting, self._forecast_scale = False, None
