"""The One Euro filter (Casiez, Roussel and Vogel, "1 Euro Filter: A Simple Speed-based Low-pass Filter for Noisy
Input in Interactive Systems", CHI 2012): an exponential low-pass whose cutoff rises with the signal's speed, so
that a face at rest does not jitter and a face that moves is followed without visible lag.

Per sample x_t at time t (seconds), dt = t - t_prev:

    alpha(fc) = 1 / (1 + tau / dt),  tau = 1 / (2 pi fc)                   (eq. 2 of the paper, as a smoothing factor)
    dx_t      = (x_t - x_prev) / dt,  dx^_t = dx^_prev + alpha(fc_d) (dx_t - dx^_prev)
    fc_t      = fc_min + beta |dx^_t|                                                                  (eq. 4)
    x^_t      = x^_prev + alpha(fc_t) (x_t - x^_prev)

The speed is the raw signal's (the paper's algorithm differences the filtered value): on a ramp it is then the
ramp's slope exactly, and the filter's lag there is slope * dt (1 - alpha) / alpha. Elementwise over a vector of
channels; beta may differ per channel (channels in degrees move faster than weights in [0, 1]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def smoothing_factor(cutoff_hz: np.ndarray | float, dt_s: float) -> np.ndarray:
    """alpha = 1 / (1 + tau / dt) with tau = 1 / (2 pi cutoff): the share of a new sample an exponential low-pass
    with this cutoff takes after dt seconds.

    >>> float(smoothing_factor(5 / math.pi, 0.1))  # tau = 0.1 s = dt
    0.5
    """
    tau = 1.0 / (2.0 * math.pi * np.asarray(cutoff_hz, np.float64))
    return 1.0 / (1.0 + tau / dt_s)


@dataclass
class OneEuro:
    """The filter's settings and its state (the last sample, its filtered value and speed)."""

    min_cutoff_hz: float = 1.5
    """The cutoff at rest: jitter above it is removed while the face holds still."""
    beta: np.ndarray | float = 0.5
    """How much the cutoff rises per unit of speed (per unit/s of each channel)."""
    d_cutoff_hz: float = 1.0
    """The cutoff of the speed's own low-pass."""
    t: float | None = None
    x: np.ndarray | None = None
    x_hat: np.ndarray | None = None
    dx_hat: np.ndarray | None = None

    def __call__(self, x: np.ndarray, t: float) -> np.ndarray:
        """The filtered value of sample x (any shape, the same each call) at time t (seconds, increasing); the
        first sample passes as it is; a sample no later than the last changes nothing."""
        x = np.asarray(x, np.float64)
        if self.t is None or self.x_hat is None or x.shape != self.x_hat.shape:
            self.t, self.x, self.x_hat, self.dx_hat = t, x, x.copy(), np.zeros_like(x)
            return self.x_hat.copy()
        dt = t - self.t
        if dt <= 0:
            return self.x_hat.copy()
        dx = (x - self.x) / dt
        self.dx_hat = self.dx_hat + smoothing_factor(self.d_cutoff_hz, dt) * (dx - self.dx_hat)
        cutoff = self.min_cutoff_hz + np.asarray(self.beta, np.float64) * np.abs(self.dx_hat)
        self.x_hat = self.x_hat + smoothing_factor(cutoff, dt) * (x - self.x_hat)
        self.t, self.x = t, x
        return self.x_hat.copy()

    def reset(self) -> None:
        self.t = self.x = self.x_hat = self.dx_hat = None
