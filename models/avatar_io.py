"""An avatar from its checkpoint folder, ready to render."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from models.avatar import Avatar, RenderConfig
from models.checkpoint import CheckpointError, load_checkpoint
from models.fields.codynerf import FieldConfig
from models.head.sources import load_head


def load_avatar(folder: str | Path) -> tuple[Avatar, dict]:
    ck = load_checkpoint(folder)
    meta = ck.meta
    try:
        field_cfg = FieldConfig(**{**meta["field"], "effects": tuple(meta["field"]["effects"])})
        render_cfg = RenderConfig(**meta["render"])
        head = load_head(meta["head_model"])
        avatar = Avatar(head, field_cfg, int(meta["frames"]), np.asarray(meta["background"], np.float32), render_cfg)
        avatar.load_state_dict(ck.weights)
    except (KeyError, TypeError, RuntimeError) as e:
        raise CheckpointError(f"{Path(folder) / 'avatar.json'}: does not describe these weights ({e})") from None
    avatar.eval()
    return avatar, meta
