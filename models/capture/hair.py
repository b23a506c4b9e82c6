"""Hair for synthetic people: a shell over the scalp, grown from the head model's own surface, that falls below it at
the sides and back for the longer styles.

The shell is a grid about the skull's centre (FaceFrame.center): a dome of directions (azimuth phi about +y, 0
ahead; elevation theta from the horizon up) and below it a curtain of horizontal rings. Each grid point stands
`thickness` off the head's surface along its direction: the surface is the furthest the head's vertices reach
within a few degrees of it (a support function over a cone, so the shell clears the scalp between vertices). In
the curtain, long hair hangs: a ring reaches no less far than the ring above it (times 0.995). Where the hair
stops is a hairline, a height for each azimuth drawn from the landmarks (forehead, temples, sideburns, round the
ears, nape for a crop; the jaw for a bob; the shoulders for long hair); the shell thins to 1.5 mm towards it and
each vertex carries its coverage (0.5 on the line), which the shader cuts with a strand-like fringe.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from models.capture.accessories import FOLLOW_HEAD, HAIR, FaceFrame, Part, clip_triangles, strip_triangles

#: Thickness of each style's shell over the crown, metres.
THICKNESS_M = {"crop": 0.006, "bob": 0.011, "long": 0.012}
MIN_THICKNESS_M = 0.0015
CONE_DEG = 7.0  # the support function's cone: wider than the grid's spacing, so no vertex pokes through
RING_M = 0.004  # the curtain's rings, metres apart


def hairline_y(style: str, frame: FaceFrame, azimuth_deg: np.ndarray) -> np.ndarray:
    """The height (canonical metres) below which a style has no hair, at each |azimuth| (degrees, 0 ahead)."""
    B, E, U = frame.brow_y, frame.eye_y, frame.face_height
    F, K = frame.ear_deg  # the ears' front and back
    T = F - 20.0  # where the hair beside the face starts to fall
    lip, chin = frame.lip_y, frame.chin_y
    if style == "crop":  # forehead, temples, a sideburn in front of the ear, over the ear, down to the nape
        knots = [(0, B + 0.42 * U), (35, B + 0.38 * U), (F - 42, B + 0.26 * U), (F - 27, B + 0.08 * U),
                 (F - 24, E - 0.06 * U), (F - 19, E - 0.06 * U), (F - 15, B + 0.02 * U), (K - 10, B - 0.02 * U),
                 (K + 10, lip), (180, lip - 0.12 * U)]
    elif style == "bob":  # a fringe, then straight down beside the face to the jaw
        knots = [(0, B + 0.16 * U), (30, B + 0.19 * U), (T - 22, B + 0.12 * U), (T - 14, chin + 0.05 * U),
                 (T, chin - 0.02 * U), (180, chin - 0.08 * U)]
    elif style == "long":  # parted over the forehead, to the shoulders
        knots = [(0, B + 0.30 * U), (30, B + 0.25 * U), (T - 22, B + 0.10 * U), (T - 14, chin - 0.15 * U),
                 (T, chin - 0.45 * U), (T + 30, chin - 0.62 * U), (180, chin - 0.68 * U)]
    else:
        raise ValueError(f"hair style {style!r}: expected crop, bob or long")
    x, y = np.array(knots, np.float64).T
    return np.interp(np.abs(azimuth_deg), x, y)


def _support(points: np.ndarray, directions: np.ndarray, cone_deg: float) -> np.ndarray:
    """(G,) the furthest any point reaches along each unit direction, among points within cone_deg of it (0 where
    none). points: (V,3) relative to the centre; directions: (G,3)."""
    dist = np.linalg.norm(points, axis=1)
    unit = (points / np.maximum(dist, 1e-9)[:, None]).astype(np.float32)
    cos_cone = np.float32(np.cos(np.radians(cone_deg)))
    out = np.zeros(len(directions))
    for k in range(0, len(directions), 256):
        c = unit @ directions[k:k + 256].T.astype(np.float32)  # (V,g)
        c[c <= cos_cone] = 0.0
        out[k:k + 256] = (c * dist[:, None].astype(np.float32)).max(0)
    return out


def _smooth_over(field: np.ndarray) -> np.ndarray:
    """A smooth field at or just above a bumpy one (rows x azimuths, wrapping round): the support function is
    ridged by the vertices it picks, and a ridged shell shows in its highlights. A 5x5 maximum, then a Gaussian
    of 1.5 cells."""
    mode = ("nearest", "wrap")
    return ndimage.gaussian_filter(ndimage.maximum_filter(field, size=5, mode=mode), 1.5, mode=mode)


def hair_part(style: str, frame: FaceFrame, head: np.ndarray, azimuths: int = 240, dome_rows: int = 48) -> Part:
    """The hair of a style as a Part that follows the skull. head: (V,3) the canonical head's skin vertices.

    Material xyz: across the strands (metres along the azimuth at 9 cm), along them (metres from the crown), the
    coverage (1 hair, 0 bare, 0.5 on the hairline)."""
    c = frame.center
    rel = head - c
    phi = np.radians(np.linspace(-180.0, 180.0, azimuths, endpoint=False))
    line_of = hairline_y(style, frame, np.degrees(phi))
    bottom = float(line_of.min()) - 0.012
    thick = THICKNESS_M[style]
    # The dome: elevation 90 (the crown, one point repeated round the azimuths) down to the horizon.
    theta = np.radians(np.linspace(90.0, 0.0, dome_rows + 1))
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.cos(th) * np.sin(ph), np.sin(th), np.cos(th) * np.cos(ph)], -1)
    reach = _support(rel, dirs.reshape(-1, 3), CONE_DEG).reshape(th.shape)
    reach = _smooth_over(np.where(reach > 0, reach, reach.max(1, keepdims=True)))  # none near: the row's furthest
    # The curtain: horizontal rings from the centre's height down past the lowest hairline.
    ring_y = c[1] - RING_M * np.arange(1, max(1, int((c[1] - bottom) / RING_M)) + 1)
    flat = np.stack([np.sin(phi), np.zeros_like(phi), np.cos(phi)], 1)
    rings, above = [], reach[-1]
    for y in ring_y:
        band = rel[np.abs(rel[:, 1] - (y - c[1])) < 0.006] * [1.0, 0.0, 1.0]
        r = _support(band, flat, CONE_DEG) if len(band) else np.zeros(len(phi))
        above = np.where(r > 0, r, above * 0.97)
        rings.append(above)
    rings = _smooth_over(np.array(rings).reshape(-1, len(phi)))
    curtain_dirs = np.broadcast_to(flat[None], (len(ring_y), len(phi), 3))
    curtain = c * [1.0, 0.0, 1.0] + rings[..., None] * curtain_dirs + ring_y[:, None, None] * [0.0, 1.0, 0.0]
    surface = np.concatenate([c + reach[..., None] * dirs, curtain])
    normal = np.concatenate([dirs, curtain_dirs])
    dome = len(theta)
    rows = len(surface)
    y = surface[..., 1]
    # Height above the hairline, measured square to it (where the line drops steeply, as beside an ear, its
    # height difference overstates the distance): divide by sqrt(1 + slope^2), slope per metre round the head.
    radius_h = np.maximum(np.hypot(surface[..., 0] - c[0], surface[..., 2] - c[2]), 0.02)
    slope = np.gradient(line_of, phi)[None] / radius_h
    above_line = (y - line_of[None]) / np.sqrt(1.0 + slope * slope)
    taper = np.clip(above_line / 0.02, 0.0, 1.0)
    thickness = MIN_THICKNESS_M + (thick - MIN_THICKNESS_M) * taper * taper * (3 - 2 * taper)
    shell = surface + thickness[..., None] * normal
    if style != "crop":
        # Hanging hair passes over the ears in one smooth swell: the horizontal radius smoothed, plus what sticks out
        # of the smooth (the ears) spread and smoothed, blended in from 50 degrees of elevation to 30; and no ring
        # of the curtain lies inside the one above it.
        rr = np.hypot(shell[..., 0] - c[0], shell[..., 2] - c[2])
        mode = ("nearest", "wrap")
        smooth = ndimage.gaussian_filter(rr, (3.0, 2.0), mode=mode)
        bump = ndimage.maximum_filter(np.maximum(rr - smooth, 0.0), size=(9, 5), mode=mode)
        swell = smooth + ndimage.gaussian_filter(bump, (3.0, 2.0), mode=mode)
        elevation = np.degrees(np.concatenate([theta, np.zeros(rows - dome)]))
        blend = np.clip((50.0 - elevation) / 20.0, 0.0, 1.0)[:, None]
        rr = np.maximum(rr, rr + blend * (swell - rr))
        for k in range(dome, rows):
            rr[k] = np.maximum(rr[k], 0.995 * rr[k - 1])
        shell[..., 0] = c[0] + rr * np.sin(phi)[None]
        shell[..., 2] = c[2] + rr * np.cos(phi)[None]
    coverage = np.clip(0.5 + above_line / 0.012, 0.0, 1.0)
    # Strand coordinates: across = azimuth at 9 cm, along = distance down from the crown.
    along = np.concatenate([0.09 * (np.pi / 2 - theta), 0.09 * np.pi / 2 + (c[1] - ring_y)])
    across = 0.09 * phi
    mats = np.stack([np.broadcast_to(across, y.shape), np.broadcast_to(along[:, None], y.shape), coverage,
                     np.full(y.shape, HAIR)], -1)
    tris = strip_triangles(rows, len(phi), wrap=True)
    # The shell ends on the hairline (coverage 0.5), so that its shadow ends there too; the shader's fringe cuts
    # inwards from it.
    tangent = np.gradient(shell, axis=0).reshape(-1, 3)  # down the rows: from the crown along the strands
    verts, mats = shell.reshape(-1, 3), mats.reshape(-1, 4)
    pairs, w, tris = clip_triangles(mats[:, 2], tris, 0.5)
    mix = lambda a: np.concatenate([a, (1 - w)[:, None] * a[pairs[:, 0]] + w[:, None] * a[pairs[:, 1]]])
    verts, mats, tangent = mix(verts), mix(mats), mix(tangent)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    used = np.unique(tris)
    renumber = np.full(len(verts), -1, np.int64)
    renumber[used] = np.arange(len(used))
    n = len(used)
    return Part(verts[used].astype(np.float32), renumber[tris].astype(np.int32), mats[used].astype(np.float32),
                np.full(n, FOLLOW_HEAD), np.zeros(n, np.int64), tangent[used].astype(np.float32))
