"""An exported avatar as a folder to host on the web: the .glb (with its animation), the player page (web/: sliders
for the expressions and the jaw, play and pause, an orbit camera) as index.html, and the parts of three.js it loads
(npm's `three`, installed into .node/ by the set-up)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from app.errors import UserInputError

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "web"
"""player.html and player.js."""
THREE = Path(os.environ.get("AVATAR_STUDIO_THREE", REPO / ".node" / "node_modules" / "three"))
"""three.js's npm package."""
THREE_FILES = ("LICENSE", "build/three.module.js", "build/three.core.js", "examples/jsm/loaders/GLTFLoader.js",
               "examples/jsm/utils/BufferGeometryUtils.js", "examples/jsm/utils/SkeletonUtils.js",
               "examples/jsm/controls/OrbitControls.js")
"""What the player imports (its import map points `three` and `three/addons/` at these), and the licence."""
GLB_NAME = "avatar.glb"


def missing_three() -> str | None:
    """Why the player's three.js cannot be copied, or None where it can."""
    lost = [f for f in THREE_FILES if not (THREE / f).is_file()]
    if lost:
        return (f"{THREE}: three.js is not installed ({lost[0]} missing): run `make setup`, or `npm install --prefix "
                f".node three@0.187.0`")
    return None


def check_web_out(out: Path) -> None:
    """A web export's folder: new, or one this command wrote before (it holds index.html), or empty."""
    if out.suffix.lower() == ".glb":
        raise UserInputError(f"{out}: --format web writes a folder (index.html, avatar.glb, three.js); name one")
    if out.exists() and not out.is_dir():
        raise UserInputError(f"{out}: is a file; --format web writes a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / "index.html").is_file():
        raise UserInputError(f"{out}: a folder that is neither empty nor a web export (no index.html)")
    why = missing_three()
    if why is not None:
        raise UserInputError(why)


def write_web_folder(out: Path, glb: bytes) -> list[Path]:
    """The player, three.js and the avatar's .glb in `out` (made if missing): the files written. Written into a
    sibling folder first and moved into place whole."""
    tmp = out.with_name(f".{out.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    shutil.copyfile(PAGE / "player.html", tmp / "index.html")
    shutil.copyfile(PAGE / "player.js", tmp / "player.js")
    for f in THREE_FILES:
        (tmp / "three" / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(THREE / f, tmp / "three" / f)
    (tmp / GLB_NAME).write_bytes(glb)
    if out.exists():
        shutil.rmtree(out)
    tmp.rename(out)
    return sorted(p for p in out.rglob("*") if p.is_file())
