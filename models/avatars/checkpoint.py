"""Avatar checkpoints (docs/formats.md): a folder with `avatar.json` (config, head-model reference, effects,
provenance, the training step) and the tensors in safetensors files. No pickle anywhere.

Crash safety: tensors go to a new file named by the step (`weights-000123.safetensors`), written to a
temporary name, fsynced and renamed; only then is `avatar.json` replaced the same way to point at it; older
tensor files are removed last. Killed at any moment, the folder holds a json that names complete files.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from models.files import atomic_write

FORMAT = "avatar-studio/checkpoint/1"
_NAME = re.compile(r"(weights|train_state)-\d{6,}\.safetensors")
_TEMPORARY = re.compile(r"\.((weights|train_state)-\d{6,}\.safetensors|avatar\.json)\..+\.tmp")
"""The temporary files atomic_write makes beside a checkpoint's files (a kill can leave one)."""


class CheckpointError(ValueError):
    """A folder that is not a readable checkpoint; the message names the file and the problem."""


@dataclass(frozen=True)
class Checkpoint:
    folder: Path
    meta: dict  # avatar.json
    weights: dict[str, torch.Tensor]
    train_state: dict[str, torch.Tensor] | None

    @property
    def step(self) -> int:
        return int(self.meta["step"])


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def save_checkpoint(folder: str | Path, meta: dict, weights: dict[str, torch.Tensor], step: int,
                    train_state: dict[str, torch.Tensor] | None = None) -> Path:
    """Write a checkpoint at `step`; `meta` must be JSON data (config, head model, effects, provenance)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    files = {"weights": f"weights-{step:06d}.safetensors"}
    tensors = {"weights": weights}
    if train_state is not None:
        files["train_state"] = f"train_state-{step:06d}.safetensors"
        tensors["train_state"] = train_state
    for kind, name in files.items():
        contiguous = {k: v.detach().cpu().contiguous() for k, v in tensors[kind].items()}
        metadata = {"format": FORMAT, "step": str(step)}
        atomic_write(folder / name, lambda tmp, c=contiguous, m=metadata: save_file(c, tmp, metadata=m))
    record = {**meta, "format": FORMAT, "step": step, "files": files}
    text = json.dumps(record, indent=1)
    atomic_write(folder / "avatar.json", lambda tmp: Path(tmp).write_text(text))
    _fsync_dir(folder)
    for old in folder.glob("*.safetensors"):
        if _NAME.fullmatch(old.name) and old.name not in files.values():
            old.unlink(missing_ok=True)
    for left in folder.glob(".*.tmp"):  # what killed writers left (the writer lock makes this run the only one)
        if _TEMPORARY.fullmatch(left.name):
            left.unlink(missing_ok=True)
    return folder / "avatar.json"


def read_meta(folder: str | Path) -> dict:
    """An avatar folder's avatar.json, checked for the fields every one has (CheckpointError names what is wrong);
    nothing else is read."""
    folder = Path(folder)
    path = folder / "avatar.json"
    if not folder.is_dir():
        raise CheckpointError(f"{folder}: no such avatar folder")
    if not path.is_file():
        raise CheckpointError(f"{folder}: not an avatar folder (no avatar.json)")
    try:
        meta = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise CheckpointError(f"{path}: not readable JSON ({e})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"{path}: field 'format' must be {FORMAT!r}")
    if not isinstance(meta.get("step"), int) or not isinstance(meta.get("files"), dict):
        raise CheckpointError(f"{path}: fields 'step' (integer) and 'files' (object) are required")
    return meta


def load_checkpoint(folder: str | Path, with_train_state: bool = False) -> Checkpoint:
    folder = Path(folder)
    path = folder / "avatar.json"
    meta = read_meta(folder)

    def read(kind: str) -> dict[str, torch.Tensor]:
        name = meta["files"].get(kind)
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise CheckpointError(f"{path}: field 'files.{kind}' must name a file beside it, got {name!r}")
        try:
            return load_file(folder / name)
        except FileNotFoundError:
            raise CheckpointError(f"{folder / name}: missing (named by avatar.json)") from None
        except (SafetensorError, OSError) as e:
            raise CheckpointError(f"{folder / name}: not a readable safetensors file ({e})") from None

    state = read("train_state") if with_train_state and "train_state" in meta["files"] else None
    return Checkpoint(folder, meta, read("weights"), state)
