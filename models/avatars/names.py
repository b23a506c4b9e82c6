"""The avatar models' names, and the prior's fine-tuning choices, without their code: `train --model`'s and
`personalize --tune`'s choices are read when the command line is built, and `--help` must start without torch. The
registry (models/avatars/registry.py) maps each name to its class; a test holds the two equal."""

from __future__ import annotations

from typing import Literal

ModelName = Literal["codynerf", "nerface", "primitives", "prior", "whole"]

PersonalTune = Literal["all", "decoder", "texel"]
"""What personalising the prior fine-tunes (PriorAvatar.tune_only): every weight, the decoder alone, or the
decoder's per-texel bias maps alone."""
