"""The One Euro filter on a step and a ramp, hand-worked. With min_cutoff = 5/pi Hz, tau = 1 / (2 pi 5/pi) = 0.1 s,
so at dt = 0.1 s alpha = 1 / (1 + 0.1/0.1) = 0.5: each sample moves the output half-way to it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.tracking.smoothing import OneEuro, smoothing_factor

DT = 0.1
FC = 5 / math.pi  # tau = 0.1 s: alpha 0.5 at DT


def run(f: OneEuro, xs: list[float]) -> list[float]:
    return [float(f(np.array([x]), k * DT)[0]) for k, x in enumerate(xs)]


def test_smoothing_factor():
    assert smoothing_factor(FC, DT) == pytest.approx(0.5)
    assert smoothing_factor(2 * FC, DT) == pytest.approx(2 / 3)  # tau 0.05: 1 / (1 + 0.5)
    assert smoothing_factor(FC, 0.3) == pytest.approx(0.75)  # 1 / (1 + 1/3)


def test_step_without_speed_term_halves_the_gap_each_sample():
    # beta 0: a plain low-pass, alpha 0.5: 0, then 0.5, 0.75, 0.875, 0.9375
    out = run(OneEuro(min_cutoff_hz=FC, beta=0.0, d_cutoff_hz=FC), [0, 1, 1, 1, 1])
    assert out == pytest.approx([0.0, 0.5, 0.75, 0.875, 0.9375])


def test_step_with_speed_term_follows_faster():
    # At the step: dx = (1 - 0) / 0.1 = 10; dx^ = 0 + 0.5 (10 - 0) = 5 (d_cutoff = FC: alpha 0.5);
    # cutoff = 5/pi + (1/pi) 5 = 10/pi: tau 0.05, alpha = 1 / (1 + 0.5) = 2/3; x^ = 2/3.
    # Next: dx = 0, dx^ = 2.5, cutoff = 5/pi + 2.5/pi = 7.5/pi: tau = 1/15, alpha = 1 / (1 + 2/3) = 0.6;
    # x^ = 2/3 + 0.6 (1 - 2/3) = 0.8667.
    out = run(OneEuro(min_cutoff_hz=FC, beta=1 / math.pi, d_cutoff_hz=FC), [0, 1, 1])
    assert out == pytest.approx([0.0, 2 / 3, 2 / 3 + 0.6 / 3])
    plain = run(OneEuro(min_cutoff_hz=FC, beta=0.0, d_cutoff_hz=FC), [0, 1, 1])
    assert out[1] > plain[1] + 0.15  # the speed term is what takes the lag away


def test_ramp_lags_by_slope_times_tau_and_less_with_speed():
    ramp = [k * DT for k in range(60)]  # x = t: slope 1 a second
    # beta 0, alpha 0.5: x^ = 0, 0.05, 0.125, 0.2125; at steady state the lag is
    # slope dt (1 - alpha) / alpha = 1 * 0.1 * 0.5 / 0.5 = 0.1 (tau).
    plain = run(OneEuro(min_cutoff_hz=FC, beta=0.0, d_cutoff_hz=FC), ramp)
    assert plain[:4] == pytest.approx([0.0, 0.05, 0.125, 0.2125])
    assert ramp[-1] - plain[-1] == pytest.approx(0.1, abs=1e-9)
    # beta = 5/pi: the speed estimate tends to the slope, 1, so the cutoff to 5/pi + 5/pi = 10/pi, alpha 2/3 and
    # the lag to 1 * 0.1 * (1/3) / (2/3) = 0.05.
    fast = run(OneEuro(min_cutoff_hz=FC, beta=5 / math.pi, d_cutoff_hz=FC), ramp)
    assert ramp[-1] - fast[-1] == pytest.approx(0.05, abs=1e-6)


def test_channels_are_filtered_apart_and_time_must_advance():
    f = OneEuro(min_cutoff_hz=FC, beta=np.array([0.0, 0.0]), d_cutoff_hz=FC)
    f(np.array([0.0, 10.0]), 0.0)
    assert f(np.array([1.0, 10.0]), DT) == pytest.approx([0.5, 10.0])
    assert f(np.array([5.0, 5.0]), DT) == pytest.approx([0.5, 10.0])  # not later: nothing changes
    # 0.3 s later, alpha 0.75: 0.5 + 0.75 (1 - 0.5) = 0.875
    assert f(np.array([1.0, 10.0]), 4 * DT)[0] == pytest.approx(0.875)
