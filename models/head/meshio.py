"""Minimal, fast OBJ reading and OBJ/PLY writing that keep the vertex order."""

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
    vertex order kept; colours (V,3) uint8: vertex colours (PLY's red/green/blue, OBJ's "v x y z r g b" in [0,1],
    which Blender and MeshLab read). The caller writes them (atomically: models/files.py)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(triangles, np.int64)
    c = None if colours is None else np.asarray(colours, np.uint8).reshape(-1, 3)
    suffix = suffix.lower()
    if suffix == ".obj":
        if c is None:
            body = "".join(f"v {x:.7g} {y:.7g} {z:.7g}\n" for x, y, z in v)
        else:
            body = "".join(f"v {x:.7g} {y:.7g} {z:.7g} {r / 255:.4g} {g / 255:.4g} {b / 255:.4g}\n"
                           for (x, y, z), (r, g, b) in zip(v, c, strict=True))
        body += "".join(f"f {a + 1} {b + 1} {c_ + 1}\n" for a, b, c_ in f)
        data = body.encode()
    elif suffix == ".ply":
        colour_props = "property uchar red\nproperty uchar green\nproperty uchar blue\n" if c is not None else ""
        header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
                  f"property float x\nproperty float y\nproperty float z\n{colour_props}"
                  f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
        vert_rec = np.zeros(len(v), dtype=[("p", "<f4", (3,))] + ([("c", "u1", (3,))] if c is not None else []))
        vert_rec["p"] = v
        if c is not None:
            vert_rec["c"] = c
        face_rec = np.zeros(len(f), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
        face_rec["n"] = 3
        face_rec["idx"] = f
        data = header.encode() + vert_rec.tobytes() + face_rec.tobytes()
    else:
        raise ValueError(f"mesh output must end in .obj or .ply, not {suffix!r}")
    return data
