"""What the program remembers for its user between runs: $XDG_CONFIG_HOME/avatar-studio/config.json (~/.config when
XDG_CONFIG_HOME is unset, or relative: the XDG rule). So far one setting, the face landmarker bundle, so that
`track` and `reenact` need --landmarker once."""

from __future__ import annotations

import json
import os
from pathlib import Path

from models.files import atomic_write_bytes


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
