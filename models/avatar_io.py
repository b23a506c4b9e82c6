"""An avatar from its checkpoint folder, ready to render."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from models.avatar import Avatar, RenderConfig
from models.checkpoint import CheckpointError, load_checkpoint
from models.device import device_of
from models.fields.codynerf import FieldConfig
from models.head.sources import load_head
from models.nerface import NerfaceAvatar, NerfaceConfig
from models.quality import load_presets


def field_config(meta: dict) -> FieldConfig:
    """The field's sizes from avatar.json (avatars written before the shadow factor existed have no light_dir)."""
    f = meta["field"]
    light = f.get("light_dir")
    return FieldConfig(**{**f, "effects": tuple(f["effects"]),
                          "light_dir": None if light is None else tuple(float(v) for v in light)})


def load_avatar(folder: str | Path, device: str = "cpu") -> tuple[Avatar | NerfaceAvatar, dict]:
    """The avatar (CoDyNeRF or the NerFACE baseline, as avatar.json says) on `device`, in eval mode."""
    ck = load_checkpoint(folder)
    meta = ck.meta
    try:
        head = load_head(meta["head_model"])
        background = np.asarray(meta["background"], np.float32)
        if meta.get("model") == "nerface":
            avatar = NerfaceAvatar(head, NerfaceConfig(**meta["nerface"]), int(meta["frames"]), background)
        else:
            field_cfg = field_config(meta)
            avatar = Avatar(head, field_cfg, int(meta["frames"]), background, RenderConfig(**meta["render"]))
        avatar.load_state_dict(ck.weights)
    except (KeyError, TypeError, RuntimeError) as e:
        raise CheckpointError(f"{Path(folder) / 'avatar.json'}: does not describe these weights ({e})") from None
    avatar.eval()
    # draft/preview/final, chosen and measured by `bench` (and where: machine, image size), else built in
    avatar.presets, avatar.presets_measured = load_presets(folder)
    return avatar.to(device_of(device)), meta
