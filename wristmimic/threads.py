"""Torch intra-op thread count for a block of work.

Small batches (one control step of 32-256 worlds, a 128-row minibatch) run fastest on one torch thread while
MuJoCo's rollout threads hold the cores: more OpenMP threads spin and contend with them (measured on 2 cores:
the policy step of evaluation 10x slower with 2 torch threads, a CPU-recipe training iteration 1.7x slower).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


@contextmanager
def torch_threads(n: int | None) -> Iterator[None]:
    """Run the block with ``n`` torch intra-op threads (None or 0: leave the count as it is), then restore it."""
    before = torch.get_num_threads()
    if not n or int(n) == before:  # nested or repeated on the hot path (every env step): nothing to change
        yield
        return
    torch.set_num_threads(int(n))
    try:
        yield
    finally:
        torch.set_num_threads(before)
