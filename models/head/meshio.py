"""Minimal, fast OBJ reading, and OBJ/PLY writing through trimesh, both keeping the vertex order."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from models.head.model import HeadModelError


def read_obj(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V,3) float64 and triangles (F,3) int64 (polygons fanned) from an OBJ file."""
    path = Path(path)
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as e:
        raise HeadModelError(f"{path}: cannot read ({e.strerror})") from None
    verts, faces = [], []
    try:
        for line in lines:
            if line.startswith("v "):
                verts.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) for t in line.split()[1:]]
                faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    except (ValueError, IndexError):
        raise HeadModelError(f"{path}: malformed OBJ line {line[:60]!r}") from None
    if not verts:
        raise HeadModelError(f"{path}: OBJ has no vertices")
    v = np.asarray(verts, np.float64)
    if v.shape[1] != 3:
        raise HeadModelError(f"{path}: OBJ vertices need 3 coordinates")
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    f = np.where(f < 0, f + len(v), f - 1)  # OBJ is 1-based; negative indices count back
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise HeadModelError(f"{path}: OBJ face indices outside its {len(v)} vertices")
    return v, f


def read_npz(path: str | Path, required: tuple[str, ...], kind: str, missing_hint: str = "") -> dict[str, np.ndarray]:
    """Every array of an npz (no pickles), after checking the `required` keys; HeadModelError otherwise."""
    path = Path(path)
    if not path.is_file():
        raise HeadModelError(f"{path}: no such file{missing_hint}")
    try:
        with np.load(path, allow_pickle=False) as d:
            missing = [k for k in required if k not in d.files]
            if missing:
                raise HeadModelError(f"{path}: {kind} npz lacks {', '.join(missing)}")
            return {k: d[k] for k in d.files}
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as e:
        raise HeadModelError(f"{path}: not a readable npz ({type(e).__name__}: {e})") from None


def mesh_bytes(suffix: str, vertices: np.ndarray, triangles: np.ndarray, colours: np.ndarray | None = None) -> bytes:
    """(V,3) vertices and (F,3) triangles as the bytes of an OBJ or a binary PLY file (suffix ".obj" or ".ply"),
    written by trimesh, vertex order kept; colours (V,3) uint8: vertex colours (PLY's red/green/blue/alpha, OBJ's
    "v x y z r g b" in [0,1], which Blender and MeshLab read). The caller writes them (atomically: models/files.py)."""
    import trimesh  # half a second to import (scipy): only when a mesh is written

    suffix = suffix.lower()
    if suffix not in (".obj", ".ply"):
        raise ValueError(f"mesh output must end in .obj or .ply, not {suffix!r}")
    c = None if colours is None else np.asarray(colours, np.uint8).reshape(-1, 3)
    # process=False: no merging or reordering, so that vertex k is the head model's vertex k
    mesh = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(triangles, np.int64), vertex_colors=c,
                           process=False)
    if suffix == ".obj":
        return trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False,
                                               header=None).encode()
    return trimesh.exchange.ply.export_ply(mesh, encoding="binary", vertex_normal=False)
