"""ICT-FaceKit (MIT) into the common HeadModel: the light npz, or the repository's FaceXModel/ OBJs.

ICT has no skinning joints: the root is rigid, each eye joint turns its eyeball's vertices about
their centroid, and the jaw opens through the `jawOpen` blend shape.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from models.head.meshio import read_npz, read_obj
from models.head.model import HeadModel, HeadModelError, Landmarks

ICT_JOINTS = ("root", "eye_l", "eye_r")
#: Vertex ranges the light model keeps from the full 26,719-vertex FaceXModel mesh (face, head and
#: neck, mouth and eye sockets, then the two eyeballs), and their [start, stop) in the kept order.
ICT_FULL_VERTICES = 26719
ICT_KEPT_RANGES = ((0, 14062), (21451, 24591))
ICT_REGIONS = {"face": (0, 9409), "head_neck": (9409, 11248), "mouth_socket": (11248, 13294),
               "eye_socket_left": (13294, 13678), "eye_socket_right": (13678, 14062),
               "eyeball_left": (14062, 15632), "eyeball_right": (15632, 17202)}
ICT_KEPT_VERTICES = 17202
NEUTRAL_OBJ = "generic_neutral_mesh.obj"
_NPZ_KEYS = ("neutral_m", "triangles", "expr_deltas_m", "expr_names", "id_deltas_m", "landmarks68")


def build_ict(
    neutral: np.ndarray,  # (V,3) metres
    triangles: np.ndarray,  # (F,3)
    expr_deltas: np.ndarray,  # (E,V,3)
    expr_names: list[str],
    id_deltas: np.ndarray,  # (S,V,3)
    landmarks68: np.ndarray | None,  # (68,) vertex ids
    regions: dict[str, tuple[int, int]],
    uv: np.ndarray | None = None,
    triangles_uv: np.ndarray | None = None,
) -> HeadModel:
    """The common form from ICT's arrays: root at the head's centroid, eye joints at eyeball centroids."""
    V = len(neutral)
    J_reg = np.zeros((3, V), np.float32)
    weights = np.zeros((V, 3), np.float32)
    weights[:, 0] = 1.0
    head_lo, head_hi = regions["face"][0], regions["head_neck"][1]
    J_reg[0, head_lo:head_hi] = 1.0 / (head_hi - head_lo)
    for j, region in ((1, "eyeball_left"), (2, "eyeball_right")):
        lo, hi = regions[region]
        J_reg[j, lo:hi] = 1.0 / (hi - lo)
        weights[lo:hi] = 0.0
        weights[lo:hi, j] = 1.0
    return HeadModel(
        name="ict",
        template=neutral.astype(np.float32),
        triangles=triangles.astype(np.int32),
        shape_basis=np.ascontiguousarray(np.transpose(id_deltas, (1, 2, 0)), dtype=np.float32),
        expr_basis=np.ascontiguousarray(np.transpose(expr_deltas, (1, 2, 0)), dtype=np.float32),
        J_regressor=J_reg,
        weights=weights,
        parents=np.array([-1, 0, 0]),
        joint_names=ICT_JOINTS,
        pose_basis=np.zeros((V, 3, 0), np.float32),
        landmarks=Landmarks(vertex_ids=None if landmarks68 is None else landmarks68.astype(np.int64)),
        expr_names=tuple(str(n) for n in expr_names),
        uv=uv,
        triangles_uv=triangles_uv,
    )


def load_ict_npz(path: str | Path) -> HeadModel:
    """The light ICT model as one npz (see shared data's README for its keys)."""
    path = Path(path)
    a = read_npz(path, _NPZ_KEYS, "ICT")
    regions = dict(ICT_REGIONS)
    if "region_names" in a:
        regions = {str(n): (int(lo), int(hi)) for n, (lo, hi) in zip(a["region_names"], a["region_ranges"],
                                                                      strict=True)}
    try:
        return build_ict(
            a["neutral_m"].astype(np.float32), a["triangles"], a["expr_deltas_m"].astype(np.float32),
            list(a["expr_names"]), a["id_deltas_m"].astype(np.float32), a["landmarks68"], regions,
            a.get("uv"), a.get("triangles_uv"),
        )
    except HeadModelError as e:
        raise HeadModelError(f"{path}: {e}") from None
    except (KeyError, ValueError, IndexError) as e:
        raise HeadModelError(f"{path}: inconsistent ICT arrays ({e})") from None


def _keep_light_vertices(v: np.ndarray, path: Path) -> np.ndarray:
    if len(v) == ICT_FULL_VERTICES:
        return np.concatenate([v[lo:hi] for lo, hi in ICT_KEPT_RANGES])
    if len(v) == ICT_KEPT_VERTICES:
        return v
    raise HeadModelError(f"{path}: {len(v)} vertices; ICT meshes have {ICT_FULL_VERTICES} "
                         f"(or {ICT_KEPT_VERTICES} in the light model)")


def _light_triangles(f: np.ndarray, full: bool) -> np.ndarray:
    if not full:
        return f
    new_index = np.full(ICT_FULL_VERTICES, -1, np.int64)
    start = 0
    for lo, hi in ICT_KEPT_RANGES:
        new_index[lo:hi] = np.arange(start, start + hi - lo)
        start += hi - lo
    g = new_index[f]
    return g[(g >= 0).all(1)]


def load_ict_folder(folder: str | Path) -> HeadModel:
    """ICT-FaceKit's FaceXModel/ folder: the neutral OBJ, one OBJ per expression and identity*.obj
    components, all in centimetres. Landmarks from `landmarks68.txt` (one vertex id a line) if present."""
    folder = Path(folder)
    if not folder.is_dir():
        raise HeadModelError(f"{folder}: no such folder")
    neutral_path = folder / NEUTRAL_OBJ
    if not neutral_path.is_file():
        raise HeadModelError(f"{folder}: not an ICT FaceXModel folder, {NEUTRAL_OBJ} is missing")
    neutral_cm, faces = read_obj(neutral_path)
    full = len(neutral_cm) == ICT_FULL_VERTICES
    neutral = _keep_light_vertices(neutral_cm, neutral_path) / 100.0
    identity_files = sorted(p for p in folder.glob("*.obj") if re.fullmatch(r"identity\d+\.obj", p.name))
    expr_files = sorted(p for p in folder.glob("*.obj") if p.name != NEUTRAL_OBJ and p not in identity_files)

    def deltas(paths: list[Path]) -> np.ndarray:
        out = np.zeros((len(paths), len(neutral), 3), np.float32)
        for k, p in enumerate(paths):
            out[k] = _keep_light_vertices(read_obj(p)[0], p) / 100.0 - neutral
        return out

    landmarks = None
    lm_file = folder / "landmarks68.txt"
    if lm_file.is_file():
        try:
            landmarks = np.loadtxt(lm_file, dtype=np.int64).ravel()
        except ValueError:
            raise HeadModelError(f"{lm_file}: landmark ids must be integers, one a line") from None
    try:
        return build_ict(neutral, _light_triangles(faces, full), deltas(expr_files),
                         [p.stem for p in expr_files], deltas(identity_files), landmarks, ICT_REGIONS)
    except HeadModelError as e:
        raise HeadModelError(f"{folder}: {e}") from None
