"""HEAD specs of the command line: `builtin`, `demo`, `ict:PATH` (npz or FaceXModel/ folder), `flame:PATH`."""

from __future__ import annotations

from pathlib import Path

from models.head.builtin import SHIPPED_PATH, head_model_from_arrays
from models.head.flame import load_flame
from models.head.ict import load_ict_folder, load_ict_npz
from models.head.meshio import read_npz
from models.head.model import HeadModel, HeadModelError

DEMO_HEAD_PATH = SHIPPED_PATH.parent / "demo_head" / "head.npz"
"""The demo's person: one ICT-FaceKit identity (MIT, LICENSE beside it), rebuilt by scripts/make_demo_head.py."""
HEAD_KINDS = ("builtin", "demo", "ict", "flame")
HEAD_SPECS = "builtin, demo, ict:PATH or flame:PATH"

_BUILTIN_KEYS = ("template", "triangles", "shape_basis", "expr_basis", "expr_names", "J_regressor",
                 "weights", "parents", "joint_names", "landmarks", "uv", "triangles_uv")


def head_kind(spec: str | None) -> str:
    """The kind of a HEAD spec (builtin, demo, ict, flame), without its path; "none" for no head model.

    >>> head_kind("ict:/data/ict_head.npz"), head_kind(None)
    ('ict', 'none')
    """
    return (spec or "none").split(":")[0]


def load_builtin(path: str | Path = SHIPPED_PATH) -> HeadModel:
    """The built-in head from its npz (as written by models.head.builtin)."""
    path = Path(path)
    arrays = read_npz(path, _BUILTIN_KEYS, "built-in head", " (rebuild it: python -m models.head.builtin)")
    try:
        return head_model_from_arrays(arrays)
    except HeadModelError as e:
        raise HeadModelError(f"{path}: {e}") from None


def load_head(spec: str) -> HeadModel:
    """A head model from a HEAD spec; HeadModelError names the file and the problem."""
    kind, _, arg = spec.partition(":")
    if kind == "builtin":
        return load_builtin(arg) if arg else load_builtin()
    if kind == "demo":
        return load_ict_npz(DEMO_HEAD_PATH)
    if kind == "ict":
        if not arg:
            raise HeadModelError("ict: needs a path, as in ict:ict_head.npz or ict:FaceXModel/")
        p = Path(arg)
        return load_ict_folder(p) if p.is_dir() else load_ict_npz(p)
    if kind == "flame":
        if not arg:
            raise HeadModelError("flame: needs a path, as in flame:generic_model.pkl")
        return load_flame(arg)
    raise HeadModelError(f"head '{spec}': expected {HEAD_SPECS}")
