"""Data-parallel motion-prior training: the worker processes, their rendezvous and the gradient exchange.

Worker 0 is the calling process; the others are spawned ("spawn" start method), build their own body model and run
the same per-worker optimisation loop (:func:`humancal.prior.train.train_motion_prior` passes its own) without
reports. The workers meet through a file rendezvous in a temporary folder and exchange over ``torch.distributed``
(gloo); :func:`average_over_workers` is the exchange of every step.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
import torch.multiprocessing as torch_mp

from humancal.prior.config import PriorConfig
from humancal.prior.data import MotionClips
from humancal.prior.model import MotionVAE

__all__ = ["EpochReport", "WorkerLoop", "average_over_workers", "optimise_with_workers"]

logger = logging.getLogger(__name__)

EpochReport = Callable[[int, int, float, dict[str, list[float]], MotionVAE], None]
"""Worker 0's end-of-epoch scoring: ``(epoch, step, lr, training terms, model)``."""

WorkerLoop = Callable[[MotionClips, PriorConfig, Any, int, int, EpochReport | None], MotionVAE]
"""The optimisation loop of one worker: ``(train_clips, config, body_model, rank, workers, report) -> model``;
``report`` is None on every worker but 0. It must be a module-level function (spawned workers receive it pickled)."""

_WORKER_TIMEOUT = timedelta(minutes=5)
"""How long a worker waits for the others (start-up, then every gradient exchange) before giving up."""


def average_over_workers(tensors: list[torch.Tensor], workers: int) -> None:
    """Replace each tensor, in place, by its mean over the workers (one all-reduce of them all, flattened)."""
    flat = torch.cat([t.reshape(-1) for t in tensors])
    dist.all_reduce(flat)
    flat /= workers
    offset = 0
    for t in tensors:
        t.copy_(flat[offset:offset + t.numel()].view_as(t))
        offset += t.numel()


def optimise_with_workers(
    optimise: WorkerLoop, train_clips: MotionClips, config: PriorConfig, body_model, workers: int, threads: int,
    report: EpochReport,
) -> MotionVAE:
    """``optimise`` as worker 0 of ``workers``, the others spawned here and joined before returning.

    Raises:
        RuntimeError: a worker failed (its traceback in the message) or the exchange broke down.
    """
    folder = Path(tempfile.mkdtemp(prefix="humancal_prior_workers_"))
    rendezvous = f"file://{folder / 'rendezvous'}"
    spawned = torch_mp.start_processes(
        _worker, args=(optimise, workers, rendezvous, train_clips, config, str(body_model.dtype),
                       str(body_model.device), threads),
        nprocs=workers - 1, join=False, start_method="spawn",
    )
    logger.info("training with %d workers of %d thread(s) each", workers, threads)
    try:
        try:
            dist.init_process_group("gloo", init_method=rendezvous, rank=0, world_size=workers,
                                    timeout=_WORKER_TIMEOUT)
            try:
                model = optimise(train_clips, config, body_model, 0, workers, report)
            finally:
                dist.destroy_process_group()
        except RuntimeError as err:  # torch.distributed's errors (a worker gone, a timeout) are RuntimeErrors
            failure = _worker_failure(spawned)
            detail = f"{err}" + (f"; a worker reported: {failure}" if failure else "")
            raise RuntimeError(f"motion-prior training with {workers} workers failed: {detail}") from err
        while not spawned.join():  # raises the error of a worker that failed after the last exchange
            pass
    finally:
        for process in spawned.processes:
            process.join(timeout=30)
            if process.is_alive():
                process.terminate()
        shutil.rmtree(folder, ignore_errors=True)
    return model


def _worker_failure(spawned) -> str:
    """The error of a spawned worker that died, or '' (waits up to 30 s for one to end)."""
    try:
        spawned.join(timeout=30)
    except (torch_mp.ProcessRaisedException, torch_mp.ProcessExitedException) as err:  # with the worker's traceback
        return str(err)
    return ""


def _worker(index: int, optimise: WorkerLoop, workers: int, rendezvous: str, train_clips: MotionClips,
            config: PriorConfig, dtype: str, device: str, threads: int) -> None:
    """Entry point of spawned worker ``index + 1``: its own body model, then ``optimise`` without reports.

    It joins the group first, so that a failure after that (the body model, say) closes its connection and worker 0
    stops at its next exchange instead of waiting out the timeout.
    """
    from humancal.body import BodyModel

    torch.set_num_threads(threads)
    dist.init_process_group("gloo", init_method=rendezvous, rank=index + 1, world_size=workers,
                            timeout=_WORKER_TIMEOUT)
    try:
        body_model = BodyModel(dtype=getattr(torch, dtype.removeprefix("torch.")), device=device)
        optimise(train_clips, config, body_model, index + 1, workers, None)
    finally:
        dist.destroy_process_group()
