"""Codes for new controls: the blend of the nearest training frames' codes, worked by hand, continuous as the
controls move, a training frame's own controls giving its own code, and the keys saved with the avatar; a
primitives training step that takes the code of its frame left out; frames of the video with a time keyed by time
as well where training chose it, and the forecast that chooses it."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import torch

from models.avatars.checkpoint import save_checkpoint
from models.avatars.components.codes import (
    FORECAST_GAP_S,
    LEFT_OUT_WINDOW,
    CodeKeys,
    left_out_weights,
    nearest_code_weights,
)
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


def clocked_keys() -> tuple[CodeKeys, list[Controls]]:
    """12 frames filmed half a second apart whose one expression weight runs 0, 1/3, 2/3, 1 and again (spread
    0.3727): frames 2, 6 and 10 have the same controls."""
    keys = CodeKeys(num_expression=1)
    controls = [Controls(expression=np.array([(i % 4) / 3], np.float32)) for i in range(12)]
    keys.note(controls, [0.5 * i for i in range(12)])
    return keys, controls


def test_a_frame_with_a_time_takes_the_codes_nearest_in_controls_and_time_where_training_chose_it():
    keys, controls = clocked_keys()
    query = controls[2]  # the controls of frames 2, 6 and 10, filmed at 5.6 s
    by_controls = torch.zeros(12)
    by_controls[[2, 6, 10]] = 1 / 3  # three at distance 0, the sixth nearest 1/3 / 0.3727 away: 1, 1, 1, 0, 0
    torch.testing.assert_close(keys.weights(query), by_controls)
    torch.testing.assert_close(keys.weights(query, 5.6), by_controls)  # no time chosen: the time changes nothing
    assert not keys.keys_time
    keys.choose_time(0.1)  # 0.1 s weighs as one spread
    assert keys.keys_time
    torch.testing.assert_close(keys.weights(query), by_controls)  # new controls (no time): by controls alone
    # With the time: frame 11 (5.5 s, 0.894 spreads off) is sqrt(0.894^2 + 1^2) = 1.342 away, frame 10 (5.0 s, the
    # same controls) 6.0, frame 9 11.04, frame 8 16.10, frame 7 21.02; the sixth, frame 6, 26.0:
    # weights 1 - d / 26 = 0.948, 0.769, 0.575, 0.381, 0.192 over their sum 2.865.
    w = keys.weights(query, 5.6)
    expected = torch.zeros(12)
    expected[[11, 10, 9, 8, 7]] = torch.tensor([0.9484, 0.7692, 0.5754, 0.3808, 0.1915]) / 2.8653
    torch.testing.assert_close(w, expected, atol=2e-4, rtol=0)
    keys.choose_time(None)
    torch.testing.assert_close(keys.weights(query, 5.6), by_controls)


def test_forecasting_blends_only_frames_filmed_a_gap_before():
    keys, controls = clocked_keys()
    # At 3.2 s, frames filmed before 3.2 - 0.3 s: 0-5. By controls among them: frame 2 at 0, frames 1, 3, 5 at
    # 0.894, frames 0 and 4 at 1.789 (the sixth): weights 1, 0.5, 0.5, 0.5 over 2.5.
    assert FORECAST_GAP_S == 0.3
    with keys.forecasting(None):
        w = keys.weights(controls[2], 3.2)
    expected = torch.zeros(12)
    expected[[2, 1, 3, 5]] = torch.tensor([0.4, 0.2, 0.2, 0.2])
    torch.testing.assert_close(w, expected)
    with keys.forecasting(0.1):  # by time as well: frame 5 (2.5 s) is nearest, none after 2.9 s
        w = keys.weights(controls[2], 3.2)
    assert w.argmax().item() == 5 and w[6:].sum() == 0 and abs(float(w.sum()) - 1) < 1e-6
    torch.testing.assert_close(keys.weights(controls[2], 3.2), keys.weights(controls[2]))  # outside: all frames
    assert keys.forecastable(2.9) and not keys.forecastable(2.7)  # 6 frames before 2.6 s, 5 before 2.4 s


def test_the_times_and_the_choice_are_saved_and_old_keys_load_without_them():
    keys, controls = clocked_keys()
    keys.choose_time(0.1)
    again = CodeKeys(num_expression=1)
    again.load_state_dict(keys.state_dict())
    assert again.keys_time
    torch.testing.assert_close(again.weights(controls[2], 5.6), keys.weights(controls[2], 5.6))
    old = CodeKeys(num_expression=1)
    old.load_state_dict({k: v for k, v in keys.state_dict().items() if k in ("keys", "scale")})
    assert not old.keys_time and old.times is None
    torch.testing.assert_close(old.weights(controls[2], 5.6), keys.weights(controls[2]))
    untimed = CodeKeys(num_expression=1)
    untimed.note(controls, [0.5] * 11 + [None])  # a frame without a time: no times kept
    assert untimed.times is None


def test_the_decoder_reads_no_gaze_beyond_what_the_training_frames_showed():
    """The primitives' decoder reads the gaze over the whole head: a gaze beyond every training frame's (a capture's
    tracked eyes are often all a little off 0, so the sliders' rest is beyond them) is read as the nearest one
    training showed, each eye's each axis held to the frames' least and most; the eyes themselves still turn with
    their joints. Worked by hand: frames' left eyes 0.1 to 0.3 about x and -0.05 to 0.05 about y, right eyes 0.2 and
    0 to 0.1; asked for left (-0.5, 0.4), right (0.15, 0.08), the decoder reads left (0.1, 0.05), right (0.2, 0.08)."""
    avatar, _ = load_avatar(DEMO)
    n = avatar.n_frames
    frames = [Controls(gaze_left=np.array([0.1 + 0.2 * k / (n - 1), 0.05 * (-1) ** k, 0.0], np.float32),
                       gaze_right=np.array([0.2, 0.1 * k / (n - 1), 0.0], np.float32)) for k in range(n)]
    asked = Controls(gaze_left=np.array([-0.5, 0.4, 0.0], np.float32),
                     gaze_right=np.array([0.15, 0.08, 0.0], np.float32))
    before = avatar.geometry(asked)  # no keys yet: read as asked
    torch.testing.assert_close(before.gaze[0], torch.tensor([-0.5, 0.4, 0.0, 0.15, 0.08, 0.0]))
    avatar.code_keys.note(frames)
    held = avatar.geometry(asked)
    torch.testing.assert_close(held.gaze[0], torch.tensor([0.1, 0.05, 0.0, 0.2, 0.08, 0.0]))
    torch.testing.assert_close(held.posed, before.posed)  # the mesh, eyes and all, posed as asked
    inside = avatar.geometry(frames[3])
    torch.testing.assert_close(inside.gaze[0], torch.as_tensor(np.r_[frames[3].gaze_left, frames[3].gaze_right]))
