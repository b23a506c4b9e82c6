"""Render quality settings and the presets an avatar offers (draft, preview, final).

`avatar-studio bench` measures settings on an avatar and stores the presets it chose from the Pareto front
of error against time in the avatar's `presets.json`, with their measured figures; avatars without one use
the built-in presets below (the studio measures those when it opens the avatar).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from models.avatars.checkpoint import CheckpointError
from models.files import atomic_write_bytes

PRESET_NAMES = ("draft", "preview", "final")


@dataclass(frozen=True)
class Quality:
    """One render setting."""

    scale: float = 1.0
    """Image size relative to the requested size (the image is rendered smaller and shown scaled up)."""
    samples: int = 12
    """Samples per ray in the shell about the surface."""
    fine: int = 0
    """Samples a second pass adds where the first pass's weights lie (0: one pass)."""
    bf16: bool = False
    """Networks in bfloat16."""

    def describe(self) -> str:
        text = f"{self.scale:g}x, {self.samples}" + (f"+{self.fine}" if self.fine else "") + " samples"
        return text + (", bf16" if self.bf16 else "")

    def size(self, size: int) -> int:
        """The image size this setting renders at for a requested size (even, at least 8)."""
        return max(8, 2 * round(size * self.scale / 2))


BUILTIN_PRESETS = {"draft": Quality(0.5, 6), "preview": Quality(1.0, 8), "final": Quality(1.0, 16)}


@dataclass(frozen=True)
class Preset:
    """A preset: its setting and, where `bench` chose it, the figures it measured."""

    quality: Quality
    ms: float | None = None
    """Median time per frame at the bench's image size on the bench's machine."""
    psnr_vs_final: float | None = None
    psnr: float | None = None
    """Against the capture's held-out test frames."""
    face_mse: float | None = None


def presets_path(folder: str | Path) -> Path:
    return Path(folder) / "presets.json"


def load_presets(folder: str | Path) -> tuple[dict[str, Preset], dict]:
    """The avatar's presets and where they were measured ({} for the built-in ones)."""
    path = presets_path(folder)
    if not path.exists():
        return {k: Preset(q) for k, q in BUILTIN_PRESETS.items()}, {}
    try:
        data = json.loads(path.read_text())
        presets = {name: Preset(Quality(**data["presets"][name]["quality"]),
                                **{k: v for k, v in data["presets"][name].items() if k != "quality"})
                   for name in PRESET_NAMES}
    except (ValueError, KeyError, TypeError) as e:
        raise CheckpointError(f"{path}: not a presets file ({e})") from None
    return presets, data.get("measured", {})


def save_presets(folder: str | Path, presets: dict[str, Preset], measured: dict) -> Path:
    """Write presets.json atomically (a reader never sees half a file)."""
    path = presets_path(folder)
    atomic_write_bytes(path, (json.dumps({"presets": {k: asdict(p) for k, p in presets.items()},
                                          "measured": measured}, indent=1) + "\n").encode())
    return path


def pareto(points: list[tuple[float, float]]) -> list[bool]:
    """For (time, error) points, whether each is on the Pareto front: no other point is as fast and as
    accurate and strictly better in one of the two.

    >>> pareto([(1.0, 5.0), (2.0, 3.0), (3.0, 4.0), (2.0, 3.0), (0.5, 9.0)])
    [True, True, False, True, True]
    """
    front = []
    for i, (t, e) in enumerate(points):
        front.append(not any(t2 <= t and e2 <= e and (t2 < t or e2 < e)
                             for j, (t2, e2) in enumerate(points) if j != i))
    return front
