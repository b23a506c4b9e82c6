"""The avatar models' names without their code: `train --model`'s choices are read when the command line is built,
and `--help` must start without torch. The registry (models/avatars/registry.py) maps each name to its class; a test
holds the two equal."""

from __future__ import annotations

from typing import Literal

ModelName = Literal["codynerf", "nerface", "primitives", "prior", "whole"]
