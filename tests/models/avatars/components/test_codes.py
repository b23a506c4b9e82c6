"""Codes for new controls: the blend of the nearest training frames' codes, worked by hand, continuous as the
controls move, a training frame's own controls giving its own code, and the keys saved with the avatar; a
primitives training step that takes the code of its frame left out."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import torch

from models.avatars.checkpoint import save_checkpoint
from models.avatars.components.codes import LEFT_OUT_WINDOW, left_out_weights, nearest_code_weights
from models.avatars.registry import load_avatar
from models.head.controls import Controls
from tests.conftest import CODYNERF_DEMO, DEMO


def test_weights_worked_by_hand():
    # keys (0,0), (3,4), (6,8), (0,10); query (0,0), k = 2: distances 0, 5, 10, 10 -> d_3 = 10;
    # weights 1 - 0/10 = 1 and 1 - 5/10 = 0.5 -> 2/3 and 1/3
    keys = torch.tensor([[0.0, 0.0], [3.0, 4.0], [6.0, 8.0], [0.0, 10.0]])
    w = nearest_code_weights(keys, torch.tensor([0.0, 0.0]), k=2)
    torch.testing.assert_close(w, torch.tensor([2 / 3, 1 / 3, 0.0, 0.0]))
    # fewer frames than k: every frame, weighted against the farthest (distances 0, 5, 10, 10 -> 1, 0.5, 0, 0)
    torch.testing.assert_close(nearest_code_weights(keys, torch.tensor([0.0, 0.0]), k=8),
                               torch.tensor([2 / 3, 1 / 3, 0.0, 0.0]))


def test_weights_change_continuously_as_the_query_moves():
    """Along a path through 40 random keys the blend never jumps, though the nearest frames change many times."""
    g = torch.Generator().manual_seed(0)
    keys = torch.randn(40, 3, generator=g, dtype=torch.float64)
    path = torch.linspace(-2, 2, 4001, dtype=torch.float64)[:, None] * torch.tensor([1.0, 0.5, -0.3],
                                                                                   dtype=torch.float64)
    ws = torch.stack([nearest_code_weights(keys, q) for q in path])
    torch.testing.assert_close(ws.sum(1), torch.ones(len(path), dtype=torch.float64))
    assert (ws >= 0).all()
    changes = (ws.argmax(1)[1:] != ws.argmax(1)[:-1]).sum().item()
    assert changes >= 5, changes  # the path does pass many frames
    step = (path[1] - path[0]).norm().item()  # 0.0012: a jump would be of order 0.2
    assert (ws[1:] - ws[:-1]).abs().max().item() < 50 * step


def test_a_training_frames_own_controls_take_its_code_and_the_keys_are_saved(tmp_path):
    avatar, meta = load_avatar(CODYNERF_DEMO)
    n = avatar.omega.num_embeddings
    rng = np.random.default_rng(3)
    controls = [Controls(expression=rng.uniform(0, 1, 6).astype(np.float32),
                         jaw=np.array([rng.uniform(0, 0.3), 0, 0], np.float32)) for _ in range(n)]
    assert avatar.code_keys.weights(controls[0]) is None  # no keys: the mean code
    avatar.code_keys.note(controls)
    j = n // 2
    w = avatar.code_keys.weights(controls[j])
    assert w.argmax().item() == j and w[j] > 0.3
    with torch.no_grad():
        avatar.omega.weight.copy_(torch.randn_like(avatar.omega.weight))
    omega, _ = avatar.codes(None, w)
    torch.testing.assert_close(omega[0], (w[:, None] * avatar.omega.weight).sum(0))
    geo = avatar.geometry(controls[j])
    torch.testing.assert_close(geo.code_weights, w)
    save_checkpoint(tmp_path / "av", json.loads(json.dumps(meta)), avatar.state_dict(), 1)
    again, _ = load_avatar(tmp_path / "av")
    torch.testing.assert_close(again.code_keys.weights(controls[j]), w)


def test_a_swapped_training_step_decodes_with_the_left_out_frames_code():
    """code_swap 1: every training step's code is the blend left_out_weights gives (never the frame's own or its
    neighbours'); code_swap 0: the frame's own."""
    avatar, _ = load_avatar(DEMO)
    n = avatar.n_frames
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        avatar.latent.weight.copy_(torch.randn(avatar.latent.weight.shape, generator=g))
    avatar.code_keys.note([Controls(expression=np.full(4, k / n, np.float32)) for k in range(n)])  # frame k at k / n
    torch.testing.assert_close(avatar.training_code(7, g), avatar.latent.weight[7:8])  # the demo's code_swap is 0
    avatar.cfg = replace(avatar.cfg, code_swap=1.0)
    w = left_out_weights(avatar.code_keys.keys, 7, window=LEFT_OUT_WINDOW)
    assert w[7 - LEFT_OUT_WINDOW:8 + LEFT_OUT_WINDOW].sum() == 0 and abs(float(w.sum()) - 1) < 1e-6
    assert w[8 + LEFT_OUT_WINDOW] > 0  # the nearest frame left in: the first after the window
    torch.testing.assert_close(avatar.training_code(7, g), w[None] @ avatar.latent.weight)
