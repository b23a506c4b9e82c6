"""FLAME (`generic_model.pkl` 2020, `flame2023.pkl`) into the common HeadModel, without chumpy."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from models.head.model import HeadModel, HeadModelError, Landmarks
from models.head.safe_pickle import UnsafePickleError, restricted_load

FLAME_JOINTS = ("root", "neck", "jaw", "eye_l", "eye_r")
#: FLAME's shapedirs hold 300 identity components, then the expression components.
FLAME_SHAPE_DIM = 300


def _read_pickle(path: Path) -> object:
    try:
        data = path.read_bytes()
    except OSError as e:
        raise HeadModelError(f"{path}: cannot read ({e.strerror})") from None
    try:
        return restricted_load(data)
    except UnsafePickleError as e:
        raise HeadModelError(f"{path}: unsafe pickle, {e}") from None
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, KeyError, IndexError,
            AttributeError, MemoryError) as e:
        raise HeadModelError(f"{path}: not a readable FLAME pickle ({type(e).__name__}: {e})") from None


def _array(d: dict, key: str, path: Path, ndim: int) -> np.ndarray:
    if key not in d:
        raise HeadModelError(f"{path}: FLAME field '{key}' is missing")
    try:
        arr = np.asarray(d[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise HeadModelError(f"{path}: FLAME field '{key}' is not numeric") from None
    if arr.ndim != ndim:
        raise HeadModelError(f"{path}: FLAME field '{key}' must have {ndim} dimensions, got shape {arr.shape}")
    return arr


def load_flame(path: str | Path, landmarks_path: str | Path | None = None) -> HeadModel:
    """A FLAME model from its pickle. Landmarks come from `flame_static_embedding.pkl` beside it,
    or the given file, when present (barycentric points on triangles)."""
    path = Path(path)
    d = _read_pickle(path)
    if not isinstance(d, dict):
        raise HeadModelError(f"{path}: a FLAME pickle holds a dict, this holds {type(d).__name__}")
    template = _array(d, "v_template", path, 2)
    V = template.shape[0]
    if template.shape[1] != 3:
        raise HeadModelError(f"{path}: FLAME field 'v_template' must be (V,3), got {template.shape}")
    faces = _array(d, "f", path, 2).astype(np.int64)
    dirs = _array(d, "shapedirs", path, 3)
    posedirs = _array(d, "posedirs", path, 3)
    J_reg = _array(d, "J_regressor", path, 2)
    weights = _array(d, "weights", path, 2)
    kintree = _array(d, "kintree_table", path, 2).astype(np.int64)
    J = kintree.shape[1]
    checks = [
        (dirs.shape[:2] == (V, 3) and dirs.shape[2] > FLAME_SHAPE_DIM, "shapedirs",
         f"(V,3,>{FLAME_SHAPE_DIM}) with V={V}", dirs.shape),
        (kintree.shape[0] == 2 and J == len(FLAME_JOINTS), "kintree_table", f"(2,{len(FLAME_JOINTS)})",
         kintree.shape),
        (J_reg.shape == (J, V), "J_regressor", f"({J},{V})", J_reg.shape),
        (weights.shape == (V, J), "weights", f"({V},{J})", weights.shape),
        (posedirs.shape == (V, 3, (J - 1) * 9), "posedirs", f"({V},3,{(J - 1) * 9})", posedirs.shape),
        (faces.shape[1:] == (3,) and len(faces) > 0 and faces.min() >= 0 and faces.max() < V, "f",
         f"(F,3) indices below {V}, F > 0", faces.shape),
    ]
    for ok, key, want, got in checks:
        if not ok:
            raise HeadModelError(f"{path}: FLAME field '{key}' must be {want}, got {got}")
    parents = kintree[0].copy()
    parents[0] = -1
    lm_path = Path(landmarks_path) if landmarks_path else path.with_name("flame_static_embedding.pkl")
    landmarks = _load_embedding(lm_path, len(faces)) if lm_path.exists() else Landmarks()
    try:
        return HeadModel(
            name="flame",
            template=template.astype(np.float32),
            triangles=faces.astype(np.int32),
            shape_basis=dirs[:, :, :FLAME_SHAPE_DIM].astype(np.float32),
            expr_basis=dirs[:, :, FLAME_SHAPE_DIM:].astype(np.float32),
            J_regressor=J_reg.astype(np.float32),
            weights=weights.astype(np.float32),
            parents=parents,
            joint_names=FLAME_JOINTS,
            pose_basis=posedirs.astype(np.float32),
            landmarks=landmarks,
        )
    except HeadModelError as e:
        raise HeadModelError(f"{path}: {e}") from None


def _load_embedding(path: Path, num_faces: int) -> Landmarks:
    d = _read_pickle(path)
    if not isinstance(d, dict) or "lmk_face_idx" not in d or "lmk_b_coords" not in d:
        raise HeadModelError(f"{path}: a landmark embedding needs 'lmk_face_idx' and 'lmk_b_coords'")
    faces = np.asarray(d["lmk_face_idx"]).astype(np.int64).ravel()
    bary = np.asarray(d["lmk_b_coords"], np.float64)
    if len(faces) == 0 or bary.shape != (len(faces), 3) or faces.min() < 0 or faces.max() >= num_faces \
            or not np.isfinite(bary).all():
        raise HeadModelError(f"{path}: landmark embedding does not fit the model's {num_faces} triangles")
    return Landmarks(faces=faces, bary=bary.astype(np.float32))
