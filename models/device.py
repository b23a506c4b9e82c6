"""Where the networks run: the --device option of train, eval and render."""

from __future__ import annotations

import torch


class DeviceError(RuntimeError):
    """A device this machine does not have."""


def device_of(name: str) -> torch.device:
    """torch.device for a --device value; a clear error where CUDA is asked for and torch sees no GPU."""
    if name == "cuda" and not torch.cuda.is_available():
        raise DeviceError("--device cuda: torch sees no CUDA GPU here (torch.cuda.is_available() is False); "
                          "use --device cpu")
    return torch.device(name)
