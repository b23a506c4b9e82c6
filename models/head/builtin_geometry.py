"""Geometry of the built-in head: a profiled surface with a face sculpted onto it, in metres.

Pure functions of vertex positions; `builtin.py` assembles the model from them. The skin is a grid of
rows (top of the head to the base of the neck) by columns (angle around the vertical axis, 0 at the
front), with slits at the mouth and the eyes, and two eyeballs.
"""

from __future__ import annotations

import numpy as np

ROWS, COLUMNS = 110, 128
MOUTH_Y, MOUTH_HALF_WIDTH = -0.035, 0.023
EYE_Y, EYE_X, EYE_HALF_WIDTH = 0.035, 0.032, 0.0135
EYEBALL_RADIUS = 0.0125

#: Midline profile of the head: height y, half-width a, front depth cf, back depth cb (metres).
_PROFILE = np.array([
    # y       a       cf      cb
    [0.148, 0.000, 0.000, -0.000],
    [0.146, 0.018, 0.018, -0.025],
    [0.140, 0.036, 0.040, -0.050],
    [0.130, 0.050, 0.060, -0.072],
    [0.110, 0.066, 0.082, -0.094],
    [0.085, 0.075, 0.095, -0.104],
    [0.060, 0.078, 0.101, -0.106],
    [0.040, 0.078, 0.099, -0.103],
    [0.020, 0.077, 0.097, -0.096],
    [0.000, 0.074, 0.097, -0.085],
    [-0.020, 0.071, 0.096, -0.072],
    [-0.040, 0.066, 0.094, -0.060],
    [-0.060, 0.058, 0.090, -0.052],
    [-0.075, 0.050, 0.083, -0.048],
    [-0.088, 0.043, 0.070, -0.047],
    [-0.096, 0.045, 0.052, -0.048],
    [-0.102, 0.050, 0.040, -0.050],
    [-0.120, 0.054, 0.037, -0.054],
    [-0.160, 0.056, 0.040, -0.058],
    [-0.200, 0.058, 0.043, -0.060],
])


def smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def gauss(x: np.ndarray, y: np.ndarray, cx: float, cy: float, sx: float, sy: float) -> np.ndarray:
    return np.exp(-0.5 * (((x - cx) / sx) ** 2 + ((y - cy) / sy) ** 2))


def row_profile() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """y, a, cf, cb for each skin row (row 0 is the crown's pole), spaced evenly along the profile."""
    from scipy.interpolate import PchipInterpolator  # (0.3 s to import: only when a head is built)

    dense_y = np.linspace(_PROFILE[0, 0], _PROFILE[-1, 0], 4000)
    # Monotone cubic through the profile's knots: smooth rows, no overshoot between knots.
    cols = [PchipInterpolator(_PROFILE[::-1, 0], _PROFILE[::-1, k])(dense_y) for k in range(1, 4)]
    step = np.sqrt(np.diff(dense_y) ** 2 + np.diff(cols[0]) ** 2 + np.diff(cols[1]) ** 2)
    s = np.concatenate([[0.0], np.cumsum(step)])
    target = np.linspace(0.0, s[-1], ROWS + 1)
    y = np.interp(target, s, dense_y)
    return y, *(np.interp(target, s, c) for c in cols)


def base_skin() -> tuple[np.ndarray, np.ndarray]:
    """Skin grid positions (ROWS+1, COLUMNS, 3) before sculpting, and the column angles phi."""
    y, a, cf, cb = row_profile()
    phi = np.linspace(-np.pi, np.pi, COLUMNS, endpoint=False)
    s, c = np.sin(phi), np.cos(phi)
    p = np.where(y < -0.1, 2.0, 2.6)[:, None]  # flatter sides on the head, round neck
    r = 1.0 / (np.abs(s) ** p + np.abs(c) ** p) ** (1.0 / p)
    depth = np.where(c >= 0, cf[:, None], -cb[:, None])
    grid = np.stack([a[:, None] * r * s, np.broadcast_to(y[:, None], r.shape), depth * r * c], -1)
    return grid, phi


def nose_height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Forward height of the nose (ridge to tip, with alae) above the face, metres."""
    ridge = np.interp(y, [-0.024, -0.014, -0.005, 0.004, 0.02, 0.036, 0.048],
                      [0.0, 0.017, 0.029, 0.027, 0.019, 0.009, 0.0])
    width = np.interp(y, [-0.02, -0.005, 0.02, 0.045], [0.011, 0.011, 0.0065, 0.008])
    alae = 0.010 * (gauss(x, y, 0.016, -0.011, 0.006, 0.006) + gauss(x, y, -0.016, -0.011, 0.006, 0.006))
    return ridge * np.exp(-0.5 * (x / width) ** 2) + alae


def eye_socket(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return gauss(x, y, EYE_X, EYE_Y, 0.016, 0.011) + gauss(x, y, -EYE_X, EYE_Y, 0.016, 0.011)


def brow_ridge(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.exp(-0.5 * ((y - 0.053 + 0.08 * x**2 / 0.05) / 0.0065) ** 2) * np.exp(-0.5 * (x / 0.045) ** 4)


def lips(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return 0.8 * gauss(x, y, 0, -0.029, 0.019, 0.0055) + 0.8 * gauss(x, y, 0, -0.042, 0.017, 0.006)


def chin(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return gauss(x, y, 0, -0.074, 0.016, 0.010)


def cheeks(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return gauss(x, y, 0.046, 0.008, 0.016, 0.014) + gauss(x, y, -0.046, 0.008, 0.016, 0.014)


def ear(p: np.ndarray) -> np.ndarray:
    """Outward (x) height of the ears: a shell with a raised rim (helix) and a hollow (concha)."""
    rho = np.sqrt(((p[..., 1] - 0.012) / 0.030) ** 2 + ((p[..., 2] + 0.014) / 0.020) ** 2)
    shell = 0.010 * np.exp(-(((rho - 0.75) / 0.28) ** 2)) + 0.007 * np.exp(-((rho / 0.6) ** 2))
    side = smoothstep(0.045, 0.065, np.abs(p[..., 0]))
    return shell * side * np.sign(p[..., 0])


def front_mask(p: np.ndarray) -> np.ndarray:
    return smoothstep(0.0, 0.045, p[..., 2])


def eyelid_opening(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far the upper and lower lids stand from the slit line when the eye is open (metres)."""
    u = np.clip(1 - ((np.abs(x) - EYE_X) / EYE_HALF_WIDTH) ** 2, 0, 1)
    return 0.0055 * u, 0.0035 * u


def sculpt(p: np.ndarray, side: np.ndarray) -> np.ndarray:
    """The neutral face on the base skin: nose, sockets, brows, cheeks, lips, chin, ears, open eyelids.

    p: (...,3) base positions; side: (...) +1 above a slit (upper lid or lip), -1 below, 0 elsewhere.
    """
    x, y = p[..., 0], p[..., 1]
    dz = (nose_height(x, y) - 0.013 * eye_socket(x, y) + 0.006 * brow_ridge(x, y) + 0.007 * cheeks(x, y)
          + 0.008 * lips(x, y) + 0.006 * chin(x, y))
    out = p.copy()
    out[..., 2] += dz * front_mask(p)
    out[..., 0] += ear(p)
    # Open the eyelids: the rim rows part, the skin around follows with a short falloff.
    up, low = eyelid_opening(x)
    near_eye = np.exp(-0.5 * ((y - EYE_Y) / 0.006) ** 2)
    above = (side > 0) | ((side == 0) & (y > EYE_Y))
    out[..., 1] += np.where(above, up, -low) * near_eye * front_mask(p)
    # The lower lip sits a millimetre under the upper one so the closed mouth shows a line.
    mouth = np.clip(1 - (x / MOUTH_HALF_WIDTH) ** 2, 0, 1) * (side < 0) * (np.abs(y - MOUTH_Y) < 0.004)
    out[..., 1] -= 0.0008 * mouth
    return out


def uv_sphere(center: np.ndarray, radius: float, rings: int = 16, segments: int = 24):
    """Vertices (N,3), triangles and (u,v) angles of a sphere whose pole points along +z."""
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    t, f = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * radius + center
    tris = []
    n = segments
    for k in range(n):
        tris.append([0, 1 + k, 1 + (k + 1) % n])
    for r in range(rings - 2):
        for k in range(n):
            a, b = 1 + r * n + k, 1 + r * n + (k + 1) % n
            tris += [[a, a + n, b], [b, a + n, b + n]]
    last = len(verts) - 1
    base = 1 + (rings - 2) * n
    for k in range(n):
        tris.append([base + k, last, base + (k + 1) % n])
    polar = np.concatenate([[0.0], t.ravel(), [np.pi]])
    return verts, np.asarray(tris), polar
