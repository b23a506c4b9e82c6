"""Writers of FLAME-format files for tests: the real FLAME cannot be downloaded here.

`write_flame_2023` writes numpy arrays (the flame2023.pkl layout); `write_flame_2020` writes what the
2020 generic_model.pkl holds: chumpy arrays and a scipy sparse J_regressor, pickled with protocol 2.
chumpy is not installed; a stand-in class registered under the module name `chumpy.ch` pickles the
same way (NEWOBJ of chumpy.ch.Ch, then its state dict with the value in 'x').
"""

from __future__ import annotations

import pickle
import sys
import types
from pathlib import Path

import numpy as np
import scipy.sparse
import scipy.spatial

V_FLAME_TEST = 600


def flame_arrays(seed: int = 0, num_vertices: int = V_FLAME_TEST, num_expr: int = 100) -> dict[str, np.ndarray]:
    """A well-formed FLAME model: 5 joints, 300 shape and `num_expr` expression components, smooth bases."""
    rng = np.random.default_rng(seed)
    # Vertices on an ellipsoid head with a neck, so that joints sit inside the surface.
    u = rng.uniform(0, 1, num_vertices)
    phi = rng.uniform(-np.pi, np.pi, num_vertices)
    theta = np.arccos(1 - 2 * u)
    v = np.stack([0.08 * np.sin(theta) * np.sin(phi), 0.11 * np.cos(theta),
                  0.1 * np.sin(theta) * np.cos(phi)], 1)
    hull = scipy.spatial.ConvexHull(v)
    faces = hull.simplices.astype(np.int64)
    joints = np.array([[0, -0.12, -0.01], [0, -0.07, -0.01], [0, -0.02, 0.0], [0.03, 0.03, 0.07],
                       [-0.03, 0.03, 0.07]])
    # J_regressor: each joint a convex combination of its 6 nearest vertices, plus a small spread.
    J_reg = np.zeros((5, num_vertices))
    for j, p in enumerate(joints):
        near = np.argsort(np.linalg.norm(v - p, axis=1))[:6]
        J_reg[j, near] = rng.dirichlet(np.ones(6))
    # Skinning weights from distances to the joints.
    d = np.linalg.norm(v[:, None] - joints[None], axis=2)
    w = np.exp(-((d / 0.05) ** 2)) + 1e-3
    w /= w.sum(1, keepdims=True)
    shapedirs = rng.normal(0, 1, (num_vertices, 3, 300 + num_expr)) * 1e-3 / np.sqrt(1 + np.arange(300 + num_expr))
    posedirs = rng.normal(0, 1e-3, (num_vertices, 3, 36))
    kintree = np.array([[4294967295, 0, 1, 1, 1], [0, 1, 2, 3, 4]], dtype=np.int64)
    return {"v_template": v, "f": faces.astype(np.uint32), "shapedirs": shapedirs, "posedirs": posedirs,
            "J_regressor": J_reg, "weights": w, "kintree_table": kintree, "J": joints,
            "bs_style": "lbs", "bs_type": "lrotmin"}


def landmark_embedding(faces: np.ndarray, seed: int = 0, count: int = 51) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed + 1)
    return {"lmk_face_idx": rng.choice(len(faces), count, replace=False).astype(np.int64),
            "lmk_b_coords": rng.dirichlet(np.ones(3), count)}


def write_flame_2023(folder: Path, arrays: dict, name: str = "FLAME_NEUTRAL.pkl") -> Path:
    """Numpy arrays and a dense J_regressor, Python 3 pickle; also flame_static_embedding.pkl."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_bytes(pickle.dumps(arrays, protocol=4))
    (folder / "flame_static_embedding.pkl").write_bytes(
        pickle.dumps(landmark_embedding(arrays["f"]), protocol=4))
    return path


class _FakeCh:
    """Pickles exactly as chumpy.ch.Ch does: NEWOBJ of the class, then a state dict holding 'x'."""

    def __init__(self, x: np.ndarray):
        self.x = x

    def __reduce_ex__(self, protocol):
        return (_newobj, (type(self),), {"x": self.x, "_dirty_vars": set(), "_itr": None})


def _newobj(cls):  # replaced by copyreg.__newobj__ through __reduce_ex__ naming
    return cls.__new__(cls)


def write_flame_2020(folder: Path, arrays: dict, name: str = "generic_model.pkl") -> Path:
    """The 2020 layout: chumpy arrays for v_template, shapedirs, posedirs, weights; sparse J_regressor."""
    import copyreg

    folder.mkdir(parents=True, exist_ok=True)
    module = types.ModuleType("chumpy.ch")
    _FakeCh.__module__, _FakeCh.__qualname__, _FakeCh.__name__ = "chumpy.ch", "Ch", "Ch"
    module.Ch = _FakeCh
    saved = {k: sys.modules.get(k) for k in ("chumpy", "chumpy.ch")}
    sys.modules["chumpy"] = types.ModuleType("chumpy")
    sys.modules["chumpy.ch"] = module
    global _newobj
    _newobj = copyreg.__newobj__
    try:
        d = dict(arrays)
        for key in ("v_template", "shapedirs", "posedirs", "weights"):
            d[key] = _FakeCh(arrays[key])
        d["J_regressor"] = scipy.sparse.csc_matrix(arrays["J_regressor"])
        path = folder / name
        path.write_bytes(pickle.dumps(d, protocol=2))
    finally:
        for k, m in saved.items():
            if m is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = m
    return path


class CommandRunningObject:
    """Unpickling this with plain pickle would run `touch MARKER`: what a malicious .pkl looks like."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        import os

        return (os.system, (f"touch {self.marker}",))


def flame_from_head(model, num_expr: int = 50) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """A FLAME-format model (arrays, static landmark embedding) with a real face's geometry: a head model
    with FLAME's five joints (root, neck, jaw, eyes; the built-in head has them), its shape and expression
    bases in shapedirs (padded to FLAME's 300 + num_expr), no pose correctives, and its iBUG landmarks 17-67
    as the 51-point static embedding."""
    V = len(model.template)
    shapedirs = np.zeros((V, 3, 300 + num_expr))
    shapedirs[..., : model.num_shape] = model.shape_basis
    shapedirs[..., 300:300 + model.num_expression] = model.expr_basis
    parents = np.asarray(model.parents, np.int64)
    kintree = np.stack([np.where(parents < 0, 4294967295, parents), np.arange(len(parents))]).astype(np.int64)
    arrays = {"v_template": model.template.astype(np.float64), "f": model.triangles.astype(np.uint32),
              "shapedirs": shapedirs, "posedirs": np.zeros((V, 3, 36)), "J_regressor": model.J_regressor,
              "weights": model.weights, "kintree_table": kintree, "bs_style": "lbs", "bs_type": "lrotmin"}
    ids = model.landmarks.vertex_ids[17:]
    faces = np.array([np.nonzero((model.triangles == i).any(1))[0][0] for i in ids], np.int64)
    bary = (model.triangles[faces] == ids[:, None]).astype(np.float64)
    return arrays, {"lmk_face_idx": faces, "lmk_b_coords": bary}


def write_flame_from_head(folder: Path, model) -> Path:
    arrays, embedding = flame_from_head(model)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "FLAME_NEUTRAL.pkl"
    path.write_bytes(pickle.dumps(arrays, protocol=4))
    (folder / "flame_static_embedding.pkl").write_bytes(pickle.dumps(embedding, protocol=4))
    return path
