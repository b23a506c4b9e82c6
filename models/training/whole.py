"""A whole-head avatar (models/avatars/whole/avatar.py) from its two trained parts: the avatar trained from scratch
on a video (`inside`) and the universal prior personalised on the same video (`outside`)."""

from __future__ import annotations

from pathlib import Path

from models.avatars.checkpoint import CheckpointError, save_checkpoint
from models.avatars.primitives.avatar import PrimitivesAvatar
from models.avatars.prior.avatar import PriorAvatar
from models.avatars.registry import load_avatar
from models.avatars.whole.avatar import WholeHeadAvatar

PART_FIELDS = ("model", "effects", "light_dir", "pose_corrections", "expression_corrections", "format", "step",
               "files", PrimitivesAvatar.config_key)
"""A part's own fields of its avatar.json (the whole's describes them under `inside` and `outside`)."""


def compose(inside_folder: Path, outside_folder: Path, out: Path) -> Path:
    """Write the whole-head avatar of two avatar folders trained on the same capture into `out` (its avatar.json's
    top is the inside's: head model, frames, views); CheckpointError naming the folder that does not fit."""
    inside, inside_meta = load_avatar(inside_folder, model=PrimitivesAvatar.name)
    outside, outside_meta = load_avatar(outside_folder, model=PriorAvatar.name)
    made = [m.get("provenance", {}) for m in (inside_meta, outside_meta)]
    datasets = [p.get("dataset_resolved") for p in made]
    if None not in datasets and datasets[0] != datasets[1]:
        raise CheckpointError(f"{outside_folder}: trained on {datasets[1]}, {inside_folder} on {datasets[0]} (the "
                              "two parts of a whole head are of one capture)")
    try:
        whole = WholeHeadAvatar(inside, outside)
    except ValueError as e:  # of two head models
        raise CheckpointError(f"{inside_folder} and {outside_folder}: {e}") from None
    top = {k: v for k, v in inside_meta.items() if k not in PART_FIELDS}
    provenance = {"dataset": made[0].get("dataset"), "dataset_resolved": datasets[0],
                  "steps": sum(int(p.get("steps", 0)) for p in made),
                  "seconds": round(sum(float(p.get("seconds", 0.0)) for p in made), 1),
                  "inside": made[0], "outside": made[1]}
    views = top.get("view_range")
    if isinstance(views, dict):  # the outside has the rest of the head: turntables and the studio's orbit go round
        top["view_range"] = {**views, "yaw_deg": [-180.0, 180.0]}
    meta = {**top, **whole.meta(), "provenance": provenance, "captured_view_range": views}
    return save_checkpoint(out, meta, whole.state_dict(), int(inside_meta["step"]))
