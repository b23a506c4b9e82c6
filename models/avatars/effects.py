"""Lighting effects an avatar models (docs/training.md): simulate only what the scene calls for; and the key light a
capture's lighting record gives the models that cast its shadows."""

from __future__ import annotations

import numpy as np

EFFECTS = ("shading", "specular", "shadows")


def parse_effects(text: str) -> tuple[str, ...]:
    """'none', 'all' or a comma list of shading, specular, shadows -> a sorted tuple."""
    text = text.strip().lower()
    if text in ("", "none"):
        return ()
    if text == "all":
        return EFFECTS
    parts = {p.strip() for p in text.split(",") if p.strip()}
    unknown = sorted(parts - set(EFFECTS))
    if unknown:
        raise ValueError(f"unknown effect(s) {unknown}: expected none, all or a comma list of {', '.join(EFFECTS)}")
    return tuple(e for e in EFFECTS if e in parts)


def effects_name(effects: list[str] | tuple[str, ...]) -> str:
    """none, all, or the effects joined by +.

    >>> effects_name([]), effects_name(EFFECTS), effects_name(["shading", "specular"])
    ('none', 'all', 'shading+specular')
    """
    return "none" if not effects else "all" if tuple(effects) == EFFECTS else "+".join(effects)


def key_light_dir(lighting: dict | None) -> tuple[float, float, float] | None:
    """The key light's direction (world, towards the light) from a capture's lighting record, if it has one
    (synthetic captures do; a tracked video does not)."""
    try:
        d = np.asarray((lighting or {})["key_light"]["direction"], np.float64)
    except (KeyError, TypeError):
        return None
    if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) < 1e-9:
        return None
    return tuple(float(v) for v in d / np.linalg.norm(d))
