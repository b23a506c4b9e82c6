"""What the program remembers for its user between runs: $XDG_CONFIG_HOME/avatar-studio/config.json (~/.config when
XDG_CONFIG_HOME is unset, or relative: the XDG rule). So far one setting, the face landmarker bundle, so that
`track` and `reenact` need --landmarker once."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

from app.errors import UserInputError
from models.files import atomic_write_bytes
from models.tracking.landmarker import packaged_bundle

LANDMARKER_URL = ("https://storage.googleapis.com/mediapipe-models/face_landmarker/face_landmarker/float16/1/"
                  "face_landmarker.task")


def config_folder() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME", "")
    return (Path(base) if os.path.isabs(base) else Path.home() / ".config") / "avatar-studio"


def _settings() -> dict:
    try:
        data = json.loads((config_folder() / "config.json").read_text())
    except (OSError, ValueError):  # none yet, or unreadable: nothing remembered
        return {}
    return data if isinstance(data, dict) else {}


def remembered(key: str) -> str | None:
    value = _settings().get(key)
    return value if isinstance(value, str) and value else None


def remember(key: str, value: str) -> Path:
    """Set one setting (the others kept); returns the config file."""
    path = config_folder() / "config.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, (json.dumps({**_settings(), key: value}, indent=1) + "\n").encode())
    return path


def find_landmarker(given: Path | None = None, packaged: Callable[[], Path | None] = packaged_bundle) -> Path:
    """The face landmarker bundle: the one given (a command's --landmarker), else $AVATAR_STUDIO_LANDMARKER, else the
    one remembered (the path a past --landmarker left in the config folder's config.json, or a face_landmarker.task
    put in that folder), else the one a Python package ships (`packaged`: models/tracking/landmarker.py's
    packaged_bundle)."""
    if given:
        return Path(given)
    if os.environ.get("AVATAR_STUDIO_LANDMARKER"):
        return Path(os.environ["AVATAR_STUDIO_LANDMARKER"])
    kept = remembered("landmarker")
    if kept and Path(kept).is_file():
        return Path(kept)
    for found in (config_folder() / "face_landmarker.task", packaged()):
        if found is not None and found.is_file():
            return found
    gone = f" (the remembered {kept} is gone)" if kept else ""
    raise UserInputError(f"no face landmarker bundle{gone}: download {LANDMARKER_URL} and pass it with --landmarker "
                         "PATH once (it is remembered for later runs)")
