"""What the hard cases share."""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture(scope="module")
def one_torch_thread() -> Iterator[None]:
    """Torch on one thread for a module of tiny tensors, the count it had put back after: a 16x16 convolution's
    forward and backward take 1 ms on one thread and 0.5 s on two while the machine's other cores are busy
    (threads spinning for each other), which a sweep of a few dozen cases turns into most of its time."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
