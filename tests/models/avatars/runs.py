"""Tiny training runs shared by the models' tests."""

from __future__ import annotations

import numpy as np
import torch

from models.avatars.registry import load_avatar


def photometric_before_and_after(trainer, steps: int) -> tuple[float, float]:
    """Run `steps` steps; the mean photometric error of the first three and of the last three."""
    first = float(np.mean([trainer.train_step(0.0)["photometric"] for _ in range(3)]))
    for k in range(3, steps - 3):
        trainer.train_step(k / steps)
    last = float(np.mean([trainer.train_step(1.0)["photometric"] for _ in range(3)]))
    return first, last


def saved_and_reloaded(trainer):
    """Save the run and load it back as an avatar folder: (avatar, meta), its weights checked equal."""
    trainer.save()
    avatar, meta = load_avatar(trainer.cfg.out)
    for k, v in trainer.avatar.state_dict().items():
        assert torch.equal(v, avatar.state_dict()[k]), k
    return avatar, meta
