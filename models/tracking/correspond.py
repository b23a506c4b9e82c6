"""Which head-model vertex each MediaPipe face landmark sits on, made from data the project has: the head
model's neutral mesh and its 68 iBUG landmarks, and MediaPipe's canonical face mesh from the user's bundle.

1. A similarity transform (scale, rotation, translation; Umeyama) takes a dozen anatomical points of the
   canonical mesh (eye corners, nose, mouth corners, chin...) onto the same points of the head model.
2. Iterative closest points refines it over all 468 points against the head's front-facing skin: vertices of
   the mesh's largest connected piece (the skin, not eyeballs, lashes or teeth, which are separate pieces)
   that a frontal orthographic view sees (not the back of the head, not the inside of the lips).
3. Each canonical point takes its nearest front-facing head vertex; points farther than `max_gap_m` from
   the head (the models disagree there) are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from models.head.model import HeadModel

# MediaPipe canonical-mesh index -> iBUG-68 landmark index, for points both name the same way.
ANCHORS = {
    1: 30,  # nose tip
    168: 27,  # top of the nose bridge
    2: 33,  # below the nose
    33: 36, 133: 39,  # subject's right eye: outer, inner corner
    362: 42, 263: 45,  # subject's left eye: inner, outer corner
    61: 48, 291: 54,  # mouth corners
    0: 51, 17: 57,  # upper lip top, lower lip bottom
    152: 8,  # chin
}


@dataclass(frozen=True)
class Correspondence:
    mp_ids: np.ndarray  # (K,) MediaPipe landmark indices used
    vertex_ids: np.ndarray  # (K,) head-model vertices they sit on
    gap_m: np.ndarray  # (K,) distance between the aligned canonical point and its vertex
    scale: float  # head-model metres per canonical-mesh metre


def umeyama(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None
            ) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity (s, R, t) minimising sum w |s R src + t - dst|^2 over (N,3) point pairs."""
    w = np.ones(len(src)) if weights is None else np.asarray(weights, np.float64)
    w = w / w.sum()
    mu_s, mu_d = w @ src, w @ dst
    a, b = src - mu_s, dst - mu_d
    cov = (b * w[:, None]).T @ a
    U, S, Vt = np.linalg.svd(cov)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = U @ D @ Vt
    var = (w * (a * a).sum(1)).sum()
    s = float(np.trace(np.diag(S) @ D) / max(var, 1e-12))
    return s, R, mu_d - s * R @ mu_s


def front_vertices(vertices: np.ndarray, cell_m: float = 0.002, depth_m: float = 0.004) -> np.ndarray:
    """Indices of the vertices a frontal orthographic view (looking down -z) sees: within depth_m of the
    frontmost vertex in their cell_m x cell_m column."""
    ij = np.floor(vertices[:, :2] / cell_m).astype(np.int64)
    ij -= ij.min(0)
    key = ij[:, 0] * (ij[:, 1].max() + 1) + ij[:, 1]
    front = np.full(key.max() + 1, -np.inf)
    np.maximum.at(front, key, vertices[:, 2])
    return np.nonzero(vertices[:, 2] >= front[key] - depth_m)[0]


def skin_vertices(model: HeadModel) -> np.ndarray:
    """Indices of the vertices of the mesh's largest connected piece."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    tri = model.triangles
    rows = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    cols = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    V = len(model.template)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(V, V))
    _, labels = connected_components(graph, directed=False)
    used = np.zeros(V, bool)
    used[tri.ravel()] = True
    counts = np.bincount(labels[used])
    return np.nonzero(labels == np.argmax(counts))[0]


def head_landmarks(model: HeadModel, vertices: np.ndarray) -> dict[int, np.ndarray]:
    """The head model's iBUG-68 landmark positions by iBUG index (FLAME's 51-point embedding starts at 17)."""
    ids, bary = model.landmarks.as_barycentric(model.triangles)
    points = (vertices[ids] * bary[..., None]).sum(1)
    first = 68 - len(points)
    if len(points) not in (51, 68):
        return {}
    return {first + k: p for k, p in enumerate(points)}


def correspond(model: HeadModel, canonical: np.ndarray, vertices: np.ndarray | None = None,
               max_gap_m: float = 0.008, iterations: int = 15) -> Correspondence:
    """Correspondences between MediaPipe's (468,3) canonical mesh and the head model's (neutral) vertices."""
    verts = model.template if vertices is None else vertices
    lms = head_landmarks(model, verts)
    pairs = [(m, i) for m, i in ANCHORS.items() if i in lms]
    if len(pairs) < 4:
        raise ValueError(f"head model '{model.name}' has no iBUG-68 landmarks to align MediaPipe's face mesh with")
    src = canonical[[m for m, _ in pairs]].astype(np.float64)
    dst = np.stack([lms[i] for _, i in pairs]).astype(np.float64)
    s, R, t = umeyama(src, dst)
    skin = skin_vertices(model)
    front = skin[front_vertices(verts[skin])]
    tree = cKDTree(verts[front])
    for _ in range(iterations):
        moved = s * canonical @ R.T + t
        gap, nearest = tree.query(moved)
        keep = gap < max(2.5 * np.median(gap), max_gap_m)
        # The anatomical anchors keep weight: ICP alone may slide the face along the head.
        s, R, t = umeyama(np.concatenate([canonical[keep], src]),
                          np.concatenate([verts[front][nearest[keep]], dst]),
                          np.concatenate([np.ones(keep.sum()), np.full(len(src), 5.0)]))
    moved = s * canonical @ R.T + t
    gap, nearest = tree.query(moved)
    ok = gap < max_gap_m
    return Correspondence(np.nonzero(ok)[0], front[nearest[ok]], gap[ok].astype(np.float32), s)
