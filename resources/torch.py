"""torch's device, threads and seed as a Dagster resource, applied for the duration of an asset's body."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import dagster as dg
import torch
from pydantic import Field

__all__ = ["TorchResource"]


class TorchResource(dg.ConfigurableResource):
    """Where and how torch runs inside an asset.

    Use as ``with torch_runtime.applied() as device: ...``: inside, torch uses ``threads`` intra-op threads and
    its global generator is seeded with ``seed``; both are restored afterwards, so one asset's settings do not
    leak into the next asset of the same process.
    """

    device: str = Field(default="cpu", description="torch device the networks run on: 'cpu', 'cuda', 'cuda:1', ...")
    threads: int | None = Field(
        default=None,
        description="torch intra-op threads; None: torch's own setting (one per physical core unless "
                    "OMP_NUM_THREADS says otherwise; on an idle 2-core machine the benchmark graph took 135 s with two "
                    "threads and 170 s with one; on a machine busy with other work one thread can be the faster)",
    )
    seed: int = Field(default=0, description="seed of torch's global generator while an asset runs")

    def torch_device(self) -> torch.device:
        """The configured device; a device that is not available here is an error, never a silent fallback.

        Raises:
            ValueError: an unknown device string, or a CUDA device without CUDA.
        """
        try:
            device = torch.device(self.device)
        except RuntimeError as err:
            raise ValueError(f"TorchResource.device={self.device!r} is not a torch device ({err})") from None
        if device.type == "cuda" and not torch.cuda.is_available():
            raise ValueError(f"TorchResource.device={self.device!r}, but CUDA is not available on this machine")
        return device

    @contextmanager
    def applied(self) -> Iterator[torch.device]:
        """Apply ``threads`` and ``seed`` while the block runs (restored afterwards); yields the device.

        Raises:
            ValueError: ``threads`` < 1, or see :meth:`torch_device`.
        """
        if self.threads is not None and self.threads < 1:
            raise ValueError(f"TorchResource.threads={self.threads} must be >= 1 (or None: torch's own setting)")
        device = self.torch_device()
        threads = torch.get_num_threads()
        rng_state = torch.random.get_rng_state()
        if self.threads is not None:
            torch.set_num_threads(self.threads)
        torch.manual_seed(self.seed)
        try:
            yield device
        finally:
            torch.set_num_threads(threads)
            torch.random.set_rng_state(rng_state)
