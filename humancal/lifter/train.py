"""Training of the lifter on 3D motion clips, validated on clips of held-out subjects.

Every ``sample_reuse`` epochs, ``samples_per_epoch`` fresh samples are synthesised from the training clips
(:func:`humancal.lifter.data.synthesize_samples`) and then trained on for ``sample_reuse`` epochs, reshuffled
each time; the validation samples are synthesised once from the
validation clips. The loss is the mean per-joint Euclidean error of the root-relative crop-frame pose, metres
(MPJPE). AdamW with a per-step cosine decay of the learning rate. Every random choice (samples, weight
initialisation, dropout, batch order) derives from ``config.seed``: the same inputs and config give the same
weights, bit for bit, on the same machine and thread count. The global torch random state is left untouched.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from humancal.lifter.config import LifterConfig
from humancal.lifter.data import LifterSamples, check_clips, synthesize_samples
from humancal.lifter.evaluate import evaluate_predictions
from humancal.lifter.infer import CHECKPOINT_FORMAT, lift_features
from humancal.lifter.model import LifterNet

__all__ = ["checkpoint_digest", "checkpoint_num_bytes", "mpjpe_loss_m", "train_lifter"]

logger = logging.getLogger(__name__)

ProgressCallback = Callable[[dict[str, Any]], None]


def mpjpe_loss_m(pred_m: torch.Tensor, target_m: torch.Tensor) -> torch.Tensor:
    """Mean per-joint Euclidean distance, metres (scalar tensor).

    Args:
        pred_m, target_m: (B, 23, 3) joints, metres.
    """
    return torch.linalg.vector_norm(pred_m - target_m, dim=-1).mean()


def _learning_rate(config: LifterConfig, step: int, total_steps: int) -> float:
    progress = min(step / max(total_steps, 1), 1.0)
    floor = config.learning_rate * config.final_lr_factor
    return floor + 0.5 * (config.learning_rate - floor) * (1.0 + math.cos(math.pi * progress))


def _subjects(clips: Sequence[tuple[str, np.ndarray]]) -> list[str]:
    return sorted({subject for subject, _ in clips})


def checkpoint_digest(checkpoint: dict[str, Any]) -> str:
    """Hex SHA-256 of what a checkpoint computes: its weights (in key order), config and subjects.

    Run-dependent entries (``training_time_s``) are left out, so two trainings with the same data, config and
    seed give the same digest, and a change of any of them gives another.
    """
    digest = hashlib.sha256()
    for name in sorted(checkpoint["state_dict"]):
        tensor = checkpoint["state_dict"][name].detach().cpu().contiguous()
        digest.update(name.encode())
        digest.update(str(tuple(tensor.shape)).encode())
        digest.update(tensor.numpy().tobytes())
    digest.update(json.dumps([checkpoint["config"], list(checkpoint["train_subjects"]),
                              list(checkpoint["val_subjects"])], sort_keys=True, default=str).encode())
    return digest.hexdigest()


def checkpoint_num_bytes(checkpoint: dict[str, Any]) -> int:
    """Bytes taken by the tensors of a checkpoint (the file adds a few kB of metadata)."""
    return sum(t.numel() * t.element_size() for t in checkpoint["state_dict"].values())


def _validate(net: LifterNet, samples, epoch: int, steps: int, train_loss: float, lr: float, start: float) -> dict:
    """The history record of ``epoch``: the network scored on the validation ``samples`` (see :func:`train_lifter`)."""
    pred = lift_features(net, samples.features)
    metrics = evaluate_predictions(pred, samples)
    return {
        "epoch": epoch,
        "steps": steps,
        "train_loss_m": train_loss,
        "val_loss_m": metrics["mpjpe_mm"] / 1000.0,
        "val_mpjpe_mm": metrics["mpjpe_mm"],
        "val_pa_mpjpe_mm": metrics["pa_mpjpe_mm"],
        "val_height_mae_mm": metrics["height_mae_mm"],
        "lr": lr,
        "elapsed_s": time.perf_counter() - start,
    }


@dataclass(frozen=True)
class _Schedule:
    """The random streams and step counts of a run, all derived from ``config.seed`` and the config.

    Attributes:
        seeds: ``config.epochs + 1`` seed sequences: index 0 draws the validation samples, index ``e`` epoch ``e``.
        total_steps: optimisation steps of the whole run (the cosine decay's length).
    """

    seeds: list[np.random.SeedSequence]
    total_steps: int


@dataclass(frozen=True)
class _EpochResult:
    """What one training epoch ends on.

    Attributes:
        step: optimisation steps taken so far (all epochs).
        lr: learning rate of the epoch's last step.
        train_loss_m: mean MPJPE loss over the epoch's batches, metres.
    """

    step: int
    lr: float
    train_loss_m: float


def _checked_clips(
    train_clips: Sequence[tuple[str, np.ndarray]], val_clips: Sequence[tuple[str, np.ndarray]]
) -> tuple[list[tuple[str, np.ndarray]], list[tuple[str, np.ndarray]]]:
    """Both clip sets checked (:func:`humancal.lifter.data.check_clips`), their subjects disjoint.

    Raises:
        ValueError: malformed clips, or a subject present in both sets.
    """
    train_clips = check_clips(train_clips, "train_clips")
    val_clips = check_clips(val_clips, "val_clips")
    shared = sorted(set(_subjects(train_clips)) & set(_subjects(val_clips)))
    if shared:
        raise ValueError(f"subjects {shared} are in both train_clips and val_clips; hold out whole subjects")
    return train_clips, val_clips


def _schedule(config: LifterConfig) -> _Schedule:
    """The run's seed sequences and step count (one step per batch, the last batch of an epoch may be short)."""
    steps_per_epoch = math.ceil(config.samples_per_epoch / config.batch_size)
    return _Schedule(
        seeds=np.random.SeedSequence(config.seed).spawn(config.epochs + 1),
        total_steps=steps_per_epoch * config.epochs,
    )


def _epoch_reporter(history: list[dict[str, Any]], progress: ProgressCallback | None) -> ProgressCallback:
    """A callback that appends an epoch record to ``history``, logs it at INFO and passes it to ``progress``."""

    def report(record: dict[str, Any]) -> None:
        history.append(record)
        logger.info(
            "epoch %d: train loss %.4f m, val MPJPE %.1f mm, PA-MPJPE %.1f mm (%.0f s)",
            record["epoch"],
            record["train_loss_m"],
            record["val_mpjpe_mm"],
            record["val_pa_mpjpe_mm"],
            record["elapsed_s"],
        )
        if progress is not None:
            progress({"kind": "epoch", **record})

    return report


def _train_epoch(
    net: LifterNet,
    optimizer: torch.optim.Optimizer,
    samples: LifterSamples,
    rng: np.random.Generator,
    epoch: int,
    step: int,
    config: LifterConfig,
    schedule: _Schedule,
    progress: ProgressCallback | None,
) -> _EpochResult:
    """One pass over ``samples`` in an order drawn from ``rng``, one AdamW step per batch.

    Args:
        samples: the training samples (features (N, 23, 3), targets (N, 23, 3) metres).
        step: optimisation steps taken before this epoch.
        progress: called with a ``{"kind": "step"}`` record every ``config.log_every_steps`` steps (also logged
            at DEBUG).
    """
    features = torch.as_tensor(samples.features)
    targets = torch.as_tensor(samples.targets_m)
    order = torch.as_tensor(rng.permutation(len(samples)))
    net.train()
    losses = []
    for first in range(0, len(samples), config.batch_size):
        rows = order[first : first + config.batch_size]
        lr = _learning_rate(config, step, schedule.total_steps)
        for group in optimizer.param_groups:
            group["lr"] = lr
        loss = mpjpe_loss_m(net(features[rows]), targets[rows])
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        step += 1
        if step % config.log_every_steps == 0:
            record = {"kind": "step", "epoch": epoch, "step": step, "loss_m": losses[-1], "lr": lr}
            logger.debug("step %d: loss %.4f m, lr %.2e", step, record["loss_m"], lr)
            if progress is not None:
                progress(record)
    return _EpochResult(step=step, lr=lr, train_loss_m=float(np.mean(losses)))


def _optimise(
    train_clips: list[tuple[str, np.ndarray]],
    val_samples: LifterSamples,
    config: LifterConfig,
    schedule: _Schedule,
    start: float,
    report: ProgressCallback,
    progress: ProgressCallback | None,
) -> LifterNet:
    """The epoch loop: a fresh sample set every ``config.sample_reuse`` epochs, validation after every epoch.

    Weight initialisation and dropout draw from a torch stream seeded with ``config.seed``, forked from the global
    one (left untouched).

    Returns:
        The trained network (eval mode).
    """
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        net = LifterNet(config.width, config.num_blocks, config.dropout)
        optimizer = torch.optim.AdamW(net.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay)
        report(_validate(net, val_samples, 0, 0, float("nan"), config.learning_rate, start))
        step = 0
        for epoch in range(1, config.epochs + 1):
            rng = np.random.default_rng(schedule.seeds[epoch])
            if (epoch - 1) % config.sample_reuse == 0:
                samples = synthesize_samples(train_clips, config.samples_per_epoch, config.samples, rng)
            result = _train_epoch(net, optimizer, samples, rng, epoch, step, config, schedule, progress)
            step = result.step
            report(_validate(net, val_samples, epoch, step, result.train_loss_m, result.lr, start))
        net.eval()
    return net


def _checkpoint(
    net: LifterNet,
    config: LifterConfig,
    train_clips: Sequence[tuple[str, np.ndarray]],
    val_clips: Sequence[tuple[str, np.ndarray]],
    val_samples: LifterSamples,
    start: float,
) -> dict[str, Any]:
    """The checkpoint dict of a trained network (see :func:`train_lifter`), its final validation included."""
    state = {name: tensor.detach().clone() for name, tensor in net.state_dict().items()}
    final = evaluate_predictions(lift_features(net, val_samples.features), val_samples)
    return {
        "format": CHECKPOINT_FORMAT,
        "state_dict": state,
        "config": config.to_dict(),
        "train_subjects": _subjects(train_clips),
        "val_subjects": _subjects(val_clips),
        "val_metrics": final,
        "training_time_s": time.perf_counter() - start,
    }


def train_lifter(
    train_clips: Sequence[tuple[str, np.ndarray]],
    val_clips: Sequence[tuple[str, np.ndarray]],
    config: LifterConfig | None = None,
    progress: ProgressCallback | None = None,
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Train a lifter.

    Args:
        train_clips: ``(subject, keypoints_world_m (F, 23, 3))`` pairs, world metres, Z up, floor z = 0.
        val_clips: the same for validation; should hold whole subjects absent from ``train_clips``.
        config: the run configuration (default :meth:`LifterConfig.default`).
        progress: called with a record every ``config.log_every_steps`` steps
            (``{"kind": "step", "epoch", "step", "loss_m", "lr"}``) and after every epoch (``{"kind": "epoch"}``
            plus the history record). Records are also logged at INFO (epochs) and DEBUG (steps).

    Returns:
        ``(checkpoint, history)``. ``checkpoint`` is a plain dict (``torch.save`` it; it loads with
        ``torch.load(weights_only=True)``): ``format``, ``state_dict`` (tensors), ``config``
        (:meth:`LifterConfig.to_dict`), ``train_subjects``, ``val_subjects``, ``val_metrics`` (of
        :func:`humancal.lifter.evaluate.evaluate_predictions`), ``training_time_s``. ``history`` has one
        record per epoch, epoch 0 being the untrained network: ``epoch, steps, train_loss_m`` (mean over the
        epoch; NaN for epoch 0), ``val_loss_m, val_mpjpe_mm, val_pa_mpjpe_mm, val_height_mae_mm, lr,
        elapsed_s``.

    Raises:
        ValueError: malformed clips, or a subject present in both sets.
    """
    config = LifterConfig.default() if config is None else config
    train_clips, val_clips = _checked_clips(train_clips, val_clips)
    start = time.perf_counter()
    schedule = _schedule(config)
    val_samples = synthesize_samples(
        val_clips, config.validation_samples, config.samples, np.random.default_rng(schedule.seeds[0])
    )
    history: list[dict[str, Any]] = []
    report = _epoch_reporter(history, progress)
    net = _optimise(train_clips, val_samples, config, schedule, start, report, progress)
    return _checkpoint(net, config, train_clips, val_clips, val_samples, start), history
