"""Torch's intra-op thread count for the duration of a call (``RetargetConfig.torch_threads``)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch

__all__ = ["torch_threads"]


@contextmanager
def torch_threads(count: int | None) -> Iterator[None]:
    """Run the block with ``torch.set_num_threads(count)`` and restore the previous count after.

    The retarget runs thousands of small batched LAPACK solves (69 x 69 per frame); with two intra-op threads on
    the 2-core development machine under load, ``torch.cholesky_solve`` on such batches took 60x longer than with
    one, and a subject's fit 11x longer. ``None`` leaves torch's setting alone.

    Args:
        count: threads to use, or ``None``.
    """
    if count is None:
        yield
        return
    previous = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)
