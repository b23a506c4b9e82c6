"""What an avatar keeps of its capture beside its trained weights (the background plate, the views, the code keys):
components whose buffers exist only where the capture gave them, saved with the weights."""

from __future__ import annotations

from typing import ClassVar

import torch
from torch import nn


class Kept(nn.Module):
    """Buffers that are None until noted, saved with the weights under the names avatar weights have always had
    (`weight_names`: the buffer's name here -> its name at the top of an avatar's weights), and made to the saved
    size when weights that hold them are loaded."""

    weight_names: ClassVar[dict[str, str]]

    def __init__(self):
        super().__init__()
        for name in self.weight_names:
            self.register_buffer(name, None)

    def keep(self, name: str, value: torch.Tensor) -> None:
        """Note one of the buffers (saved with the weights from now on)."""
        self.register_buffer(name, value)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        for name in self.weight_names:
            if prefix + name in state_dict:
                self.register_buffer(name, torch.empty_like(state_dict[prefix + name]))
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)


def keep_weight_names(module: nn.Module) -> None:
    """Save the Kept children's buffers of `module` under their weight names (`plate`, not `plate.image`) and read
    them back from those: weights written before the buffers were components load, and new ones read the same."""
    module.register_state_dict_post_hook(_to_weight_names)
    module.register_load_state_dict_pre_hook(_from_weight_names)


def _weight_names(module: nn.Module, prefix: str) -> dict[str, str]:
    """Each Kept child's buffer as state_dict names it -> its weight name."""
    return {f"{prefix}{child}.{name}": prefix + flat for child, part in module.named_children()
            if isinstance(part, Kept) for name, flat in part.weight_names.items()}


def _to_weight_names(module, state_dict, prefix, _metadata) -> None:
    for nested, flat in _weight_names(module, prefix).items():
        if nested in state_dict:
            state_dict[flat] = state_dict.pop(nested)


def _from_weight_names(module, state_dict, prefix, *_) -> None:
    for nested, flat in _weight_names(module, prefix).items():
        if flat in state_dict:
            state_dict[nested] = state_dict.pop(flat)
