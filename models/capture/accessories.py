"""Geometry a synthetic person has beyond the head model's mesh (hair, teeth, lashes), built in the head's canonical
space from its landmarks, so that it fits any head model, and posed with the head every frame.

Each part follows the head one of three ways: rigidly with the skull (hair, upper teeth), rigidly with the jaw
(lower teeth), or with one head vertex it is anchored to, turned as the skull turns (lashes on the eyelid). The
skull's and the jaw's rigid motions are measured on the posed mesh itself (Kabsch on the scalp's and the chin's
vertices), so a head model needs no joints for them: ICT opens its jaw with a blendshape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from render.mesh import vertex_normals

#: Material ids of the capture shader (the w of the material attribute).
SKIN, EYE, HAIR, TEETH, LASHES = 0.0, 1.0, 2.0, 3.0, 4.0
FOLLOW_HEAD, FOLLOW_JAW, FOLLOW_ANCHOR = 0, 1, 2


@dataclass(frozen=True)
class FaceFrame:
    """Where a head's features are, in canonical metres, read from its 68 landmarks and its vertices."""

    landmarks: np.ndarray  # (68,3); the jaw line (0-16) may be NaN (FLAME's embedding has none)
    center: np.ndarray  # (3,) the skull's centre: midline, brow height, halfway between forehead and occiput
    brow_y: float
    eye_y: float
    lip_y: float  # where the lips meet
    chin_y: float
    ear_deg: tuple[float, float]  # azimuths about the centre (0 ahead, 90 to the side) of the ears' front and back
    scalp_ids: np.ndarray  # (S,) vertices that move only with the skull
    chin_ids: np.ndarray  # (C,) vertices that move with the jaw

    @property
    def face_height(self) -> float:
        return self.brow_y - self.chin_y


def face_frame(canonical: np.ndarray, landmarks: np.ndarray, rigid_ids: np.ndarray) -> FaceFrame:
    """canonical: (V,3) neutral head; landmarks: (68,3); rigid_ids: vertices that are skin (not eyeballs)."""
    lm = landmarks
    brow_y = float(lm[17:27, 1].mean())
    eye_y = float(lm[36:48, 1].mean())
    lip_y = float(lm[60:68, 1].mean())
    chin = lm[8] if np.isfinite(lm[8]).all() else lm[57] - [0.0, 0.035, 0.01]
    skin = canonical[rigid_ids]
    midline = skin[(np.abs(skin[:, 0] - lm[27, 0]) < 0.02) & (skin[:, 1] > brow_y)]
    center = np.array([lm[36:48, 0].mean(), brow_y, 0.5 * (midline[:, 2].min() + midline[:, 2].max())])
    d = skin - center
    height = float(brow_y - chin[1])
    up = np.degrees(np.arctan2(d[:, 1], np.hypot(d[:, 0], d[:, 2])))
    scalp = rigid_ids[(up > 35.0) | ((d[:, 2] < -0.03) & (skin[:, 1] > eye_y))]
    jaw_point = 0.6 * chin + 0.4 * lm[57]
    near = np.linalg.norm(skin - jaw_point, axis=1) < 0.3 * height
    chin_ids = rigid_ids[near & (skin[:, 2] > jaw_point[2] - 0.02) & (skin[:, 1] < lm[57, 1])]
    ears = ear_azimuths(d, brow_y - center[1], eye_y - center[1])
    return FaceFrame(lm, center, brow_y, eye_y, lip_y, float(chin[1]), ears, scalp, chin_ids)


def ear_azimuths(d: np.ndarray, brow_dy: float, eye_dy: float, step_deg: float = 5.0) -> tuple[float, float]:
    """Where the ears are round the head: the azimuths (both sides folded together, from 55 degrees back) at which
    the head reaches more than 8 mm further out between eye and brow height than just above the brows. d: (V,3) skin
    vertices about the skull's centre; brow_dy, eye_dy: the brows' and eyes' heights about it. (90, 112) where
    nothing sticks out."""
    azimuth = np.degrees(np.arctan2(np.abs(d[:, 0]), d[:, 2]))
    radius = np.hypot(d[:, 0], d[:, 2])
    band = (d[:, 1] > eye_dy - 0.01) & (d[:, 1] < brow_dy)
    above = (d[:, 1] > brow_dy + 0.015) & (d[:, 1] < brow_dy + 0.035)
    starts = np.arange(55.0, 150.0, step_deg)
    out = []
    for a in starts:
        inside = (azimuth >= a) & (azimuth < a + step_deg)
        if (band & inside).any() and (above & inside).any():
            out.append(radius[band & inside].max() - radius[above & inside].max() > 0.008)
        else:
            out.append(False)
    ear = starts[np.array(out, bool)]
    return (float(ear.min()), float(ear.max() + step_deg)) if len(ear) else (90.0, 112.0)


@dataclass(frozen=True)
class Part:
    """A piece of geometry in canonical space and how it follows the head."""

    canonical: np.ndarray  # (N,3) metres
    triangles: np.ndarray  # (F,3) into this part's vertices
    material: np.ndarray  # (N,4): xyz the material's own coordinates, w its id
    follow: np.ndarray  # (N,) FOLLOW_HEAD, FOLLOW_JAW or FOLLOW_ANCHOR
    anchor: np.ndarray  # (N,) head vertex each FOLLOW_ANCHOR vertex moves with (else 0)
    tangent: np.ndarray  # (N,3) the direction strands run (hair), else 0


def join_parts(parts: list[Part]) -> Part:
    """One part of many (triangles renumbered)."""
    offsets = np.cumsum([0] + [len(p.canonical) for p in parts])
    return Part(np.concatenate([p.canonical for p in parts]).astype(np.float32),
                np.concatenate([p.triangles + o for p, o in zip(parts, offsets, strict=False)]).astype(np.int32),
                np.concatenate([p.material for p in parts]).astype(np.float32),
                np.concatenate([p.follow for p in parts]), np.concatenate([p.anchor for p in parts]),
                np.concatenate([p.tangent for p in parts]).astype(np.float32))


def rigid_fit(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation R and translation t minimising sum |R source_i + t - target_i|^2 (Kabsch, 1976).

    source, target: (N,3). Returns R (3,3), t (3,).

    >>> R, t = rigid_fit(np.eye(3), np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]) + 2.0)  # 90 deg about z
    >>> np.round(R @ [1.0, 0, 0] + t, 6).tolist()  # x -> y, y -> -x, shifted by 2
    [2.0, 3.0, 2.0]
    """
    mu_s, mu_t = source.mean(0), target.mean(0)
    H = (source - mu_s).T @ (target - mu_t)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, mu_t - R @ mu_s


def pose_part(part: Part, frame: FaceFrame, canonical: np.ndarray, posed: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """(N,3) the part's vertices on the posed head, and (N,3) its tangents turned with them. canonical, posed:
    (V,3) the head's vertices."""
    R_head, t_head = rigid_fit(canonical[frame.scalp_ids], posed[frame.scalp_ids])
    R_jaw, t_jaw = rigid_fit(canonical[frame.chin_ids], posed[frame.chin_ids])
    p = part.canonical.astype(np.float64)
    out = p @ R_head.T + t_head
    jaw = part.follow == FOLLOW_JAW
    out[jaw] = p[jaw] @ R_jaw.T + t_jaw
    on = part.follow == FOLLOW_ANCHOR
    a = part.anchor[on]
    out[on] = posed[a] + (p[on] - canonical[a]) @ R_head.T
    tangent = np.where(jaw[:, None], part.tangent @ R_jaw.T, part.tangent @ R_head.T)
    return out.astype(np.float32), tangent.astype(np.float32)


def strip_triangles(rows: int, cols: int, wrap: bool = False) -> np.ndarray:
    """(F,3) triangles of a rows x cols grid of vertices (row-major), two per cell; wrap joins the last column
    to the first.

    >>> strip_triangles(2, 2).tolist()
    [[0, 2, 1], [1, 2, 3]]
    """
    c_end = cols if wrap else cols - 1
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(c_end), indexing="ij")
    a = r * cols + c
    b = r * cols + (c + 1) % cols
    tris = np.stack([np.stack([a, a + cols, b], -1), np.stack([b, a + cols, b + cols], -1)], 2)
    return tris.reshape(-1, 3).astype(np.int32)


def clip_triangles(values: np.ndarray, triangles: np.ndarray, level: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut a triangle mesh where a per-vertex value crosses `level`, keeping the side at or above it.

    values: (N,) per vertex; triangles: (F,3). Returns the new vertices as (K,2) vertex pairs and (K,) weights (the
    point (1 - w) * a + w * b on edge a-b, for any per-vertex attribute), and triangles over the N old vertices then
    the K new ones (those wholly below the level dropped).

    >>> pairs, w, tris = clip_triangles(np.array([1.0, 0.0, 0.0]), np.array([[0, 1, 2]]), 0.5)
    >>> pairs.tolist(), w.tolist(), tris.tolist()
    ([[0, 1], [0, 2]], [0.5, 0.5], [[0, 3, 4]])
    """
    above = values[triangles] >= level  # (F,3)
    count = above.sum(1)
    out = [triangles[count == 3]]
    edges: dict[tuple[int, int], int] = {}
    pairs: list[tuple[int, int]] = []
    n = len(values)

    def cut(a: int, b: int) -> int:
        key = (min(a, b), max(a, b))
        if key not in edges:
            edges[key] = n + len(pairs)
            pairs.append(key)
        return edges[key]

    new = []
    for tri, up in zip(triangles[(count == 1) | (count == 2)], above[(count == 1) | (count == 2)], strict=True):
        k = int(np.flatnonzero(up != (up.sum() == 2))[0])  # the vertex alone on its side
        a, b, c = (int(tri[(k + j) % 3]) for j in range(3))  # the same winding, starting from it
        ab, ac = cut(a, b), cut(a, c)
        new += [(a, ab, ac)] if up.sum() == 1 else [(ab, b, c), (ab, c, ac)]
    pair_arr = np.array(pairs, np.int64).reshape(-1, 2)
    w = (level - values[pair_arr[:, 0]]) / (values[pair_arr[:, 1]] - values[pair_arr[:, 0]])
    out.append(np.array(new, np.int64).reshape(-1, 3))
    return pair_arr, w, np.concatenate(out).astype(np.int32)


def teeth_parts(frame: FaceFrame) -> list[Part]:
    """An upper and a lower row of teeth behind the lips: arches (half-ellipses seen from above) as wide as the
    mouth, the upper row's edge 5.5 mm below where the lips meet and 1.5 mm in front of the lower's (an overbite),
    hidden while the lips are closed. Material xyz: arch length from the midline (m), height from the biting
    edge towards the gum (0..1), row (0 upper, 1 lower)."""
    lm = frame.landmarks
    width = float(np.linalg.norm(lm[54] - lm[48]))
    a, b = 0.5 * width, 0.028  # the arch's half-width and depth, metres
    z_front = float(lm[[61, 62, 63, 65, 66, 67], 2].max()) - 0.0095  # the lips' thickness in front
    x0, y0 = float(lm[62, 0]), frame.lip_y
    psi = np.radians(np.linspace(-80.0, 80.0, 33))
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(a * np.sin(psi)), np.diff(b * np.cos(psi))))])
    arc -= np.interp(0.0, psi, arc)
    inward = np.stack([-b * np.sin(psi), np.zeros_like(psi), -a * np.cos(psi)], 1)  # towards the arch's inside
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    parts = []
    for row, (top, bottom, dz, follow) in enumerate([(y0 + 0.007, y0 - 0.0055, 0.0, FOLLOW_HEAD),
                                                     (y0 - 0.004, y0 - 0.014, -0.0015, FOLLOW_JAW)]):
        edge, gum = (bottom, top) if row == 0 else (top, bottom)
        front = np.stack([x0 + a * np.sin(psi), np.zeros_like(psi), z_front + dz - b * (1 - np.cos(psi))], 1)
        profile = [(0.0, gum, 1.0), (0.0, edge, 0.0), (0.006, edge, 0.0), (0.006, gum, 1.0)]  # (depth, y, height)
        verts, mats = [], []
        for depth, y, h in profile:
            verts.append(front + depth * inward + [0.0, y, 0.0])
            mats.append(np.stack([arc, np.full_like(arc, h), np.full_like(arc, row), np.full_like(arc, TEETH)], 1))
        verts_a = np.concatenate(verts)
        tris = strip_triangles(len(profile), len(psi))
        if row == 1:
            tris = tris[:, ::-1]  # the lower row's profile runs the other way round: keep faces outward
        n = len(verts_a)
        parts.append(Part(verts_a, tris, np.concatenate(mats), np.full(n, follow), np.zeros(n, np.int64),
                          np.zeros((n, 3))))
    return parts


def lash_parts(frame: FaceFrame, canonical: np.ndarray, rigid_ids: np.ndarray) -> list[Part]:
    """Upper lashes: a strip along each upper lid's margin (landmarks 36-39 and 42-45), 7 mm long, leaning forward
    and up, each column anchored to the lid vertex nearest its root, so the lashes close with a blink. Material
    xyz: position along the lid (0 to 1), along the lash (0 root to 1 tip), 0."""
    lm = frame.landmarks
    parts = []
    for ids in ((36, 37, 38, 39), (45, 44, 43, 42)):  # each from the outer corner in
        pts = lm[list(ids)]
        s = np.linspace(0.0, 3.0, 19)
        root = np.stack([np.interp(s, np.arange(4), pts[:, k]) for k in range(3)], 1)
        root[1:-1] += [0.0, 0.0008, 0.0008]
        outward = np.sign(pts[0, 0] - pts[3, 0])
        t = s / 3.0
        lean = np.stack([outward * 0.35 * (1 - t), 0.55 + 0.1 * t, np.ones_like(t)], 1)
        lean /= np.linalg.norm(lean, axis=1, keepdims=True)
        length = 0.0075 * (0.6 + 0.4 * np.sin(np.pi * np.clip(0.15 + 0.8 * t, 0, 1)))
        tip = root + lean * length[:, None]
        skin = canonical[rigid_ids]
        nearest = rigid_ids[np.argmin(((root[:, None] - skin[None]) ** 2).sum(-1), axis=1)]
        verts = np.concatenate([root, tip])
        mats = np.concatenate([np.stack([t, np.zeros_like(t), np.zeros_like(t), np.full_like(t, LASHES)], 1),
                               np.stack([t, np.ones_like(t), np.zeros_like(t), np.full_like(t, LASHES)], 1)])
        n = len(verts)
        parts.append(Part(verts, strip_triangles(2, len(s)), mats, np.full(n, FOLLOW_ANCHOR),
                          np.concatenate([nearest, nearest]), np.zeros((n, 3))))
    return parts


def mouth_interior(canonical: np.ndarray, triangles: np.ndarray, frame: FaceFrame) -> np.ndarray:
    """(V,) 1 for the head's vertices inside the mouth (behind the closed lips: a ray from the vertex straight
    ahead meets the lips, and the vertex does not face backwards), else 0."""
    lips = frame.landmarks[48:68]
    box_lo, box_hi = lips.min(0) - [0.012, 0.015, 0.02], lips.max(0) + [0.012, 0.015, 0.02]
    tri_pts = canonical[triangles]
    tri_pts = tri_pts[((tri_pts.min(1) < box_hi) & (tri_pts.max(1) > box_lo)).all(1)]
    # A ray along +z from (x, y, z) meets a triangle where (x, y) is inside its projection on the xy plane and the
    # triangle's z there is ahead of z. The mouth reaches wider than the lips and 12 cm behind them; the nape,
    # behind it, faces backwards, the mouth's walls face into it.
    lo, hi = lips.min(0) - [0.02, 0.03, 0.12], lips.max(0) + [0.02, 0.02, 0.0]
    facing = vertex_normals(canonical, triangles)[:, 2] > -0.5
    cand = np.flatnonzero(((canonical > lo) & (canonical < hi)).all(1) & facing)
    out = np.zeros(len(canonical), np.float32)
    if not len(cand) or not len(tri_pts):
        return out
    a, b, c = tri_pts[:, 0], tri_pts[:, 1], tri_pts[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = np.abs(det) > 1e-14  # triangles seen edge-on from the front have no area to meet
    a, b, c, det = a[ok], b[ok], c[ok], det[ok]
    for k in range(0, len(cand), 512):
        p = canonical[cand[k:k + 512], None, :]
        dx, dy = p[..., 0] - a[:, 0], p[..., 1] - a[:, 1]
        u = (dx * (c[:, 1] - a[:, 1]) - dy * (c[:, 0] - a[:, 0])) / det
        v = (dy * (b[:, 0] - a[:, 0]) - dx * (b[:, 1] - a[:, 1])) / det
        z = a[:, 2] + u * (b[:, 2] - a[:, 2]) + v * (c[:, 2] - a[:, 2])
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (z > p[..., 2] + 0.0005)
        out[cand[k:k + 512]] = hit.any(1)
    return out
