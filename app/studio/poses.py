"""Named poses of an avatar's sliders, kept for each avatar (by its folder's absolute path) in one file in the
user's config folder, so that poses survive the session and never write into an avatar folder (the shipped demo
may be read-only). A pose is the face's channels (app/animation.py: expressions by name, head, neck, jaw, gaze);
the camera is not part of it, so recalling a pose keeps the view.

    {"format": "avatar-studio/poses/1",
     "avatars": {"/home/me/avatars/anna": {"surprise": {"jaw.open": 14.0, "expression.browRaise_L": 0.8, ...}}}}

A file that cannot be read is never overwritten: PosesError says which file and why, and nothing is saved until
it is fixed or moved away."""

from __future__ import annotations

import json
import math
from pathlib import Path

from app.animation import all_channels, channel_value, read_format_file, set_channel
from models.files import atomic_write_bytes
from models.head.model import HeadModel

FORMAT = "avatar-studio/poses/1"
POSES_FILE = Path.home() / ".config" / "avatar-studio" / "poses.json"


class PosesError(ValueError):
    """The poses file cannot be used; the message names it and the problem."""


def read_poses(path: Path = POSES_FILE) -> dict[str, dict[str, dict[str, float]]]:
    """Every avatar's poses: folder -> name -> channel -> value (nothing where there is no file yet)."""
    if not path.exists():
        return {}
    after = "; poses are not saved until it is fixed or moved away"
    data = read_format_file(path, FORMAT, "a poses file", PosesError, after)
    if not isinstance(data.get("avatars"), dict):
        raise PosesError(f"{path}: its \"avatars\" is not an object{after}")
    out: dict[str, dict[str, dict[str, float]]] = {}
    for folder, poses in data["avatars"].items():
        if not isinstance(poses, dict):
            raise PosesError(f"{path}: the poses of {folder} are not an object")
        for name, channels in poses.items():
            try:
                values = {str(c): float(v) for c, v in dict(channels).items()}
            except (TypeError, ValueError):
                raise PosesError(f"{path}: pose {name!r} of {folder}: channels must map to numbers") from None
            if not all(math.isfinite(v) for v in values.values()):
                raise PosesError(f"{path}: pose {name!r} of {folder}: values must be finite")
            out.setdefault(str(folder), {})[str(name)] = values
    return out


def write_poses(all_poses: dict[str, dict[str, dict[str, float]]], path: Path = POSES_FILE) -> None:
    data = {"format": FORMAT, "avatars": {f: dict(sorted(p.items())) for f, p in sorted(all_poses.items()) if p}}
    atomic_write_bytes(path, (json.dumps(data, indent=1) + "\n").encode())


def avatar_key(folder: Path) -> str:
    return str(Path(folder).resolve())


def face_channels(head: HeadModel) -> list[str]:
    """The channels a pose holds: every one but the camera's."""
    return [c for c in all_channels(head) if not c.startswith("camera.")]


def pose_of(sliders, view, head: HeadModel) -> dict[str, float]:
    return {c: round(channel_value(sliders, view, head, c), 6) for c in face_channels(head)}


def apply_pose(pose: dict[str, float], sliders, view, head: HeadModel) -> None:
    """The pose's channels onto the sliders; channels the head model lacks (a pose saved with another head) are
    skipped, and channels the pose lacks go to rest."""
    known = set(face_channels(head))
    for channel in known:
        set_channel(sliders, view, head, channel, float(pose.get(channel, 0.0)))
