"""Training of the motion prior on retargeted mocap clips, with whole subjects held out.

Every optimisation step draws a fresh batch of augmented windows from the training clips
(:func:`humancal.prior.data.sample_windows`), encodes them, decodes a sampled latent and minimises the loss of
:mod:`humancal.prior.losses` (the KL weight grows linearly over the first ``kl_anneal_epochs`` epochs). AdamW
with a per-step cosine decay of the learning rate. After every epoch the model reconstructs fixed held-out
windows (plain: speed 1, forward, not mirrored) from their posterior means and is scored by the MPJPE of the 23
canonical keypoints (root at the origin, identity root rotation; :func:`humancal.prior.losses.pose_keypoints_m`).

Data parallel on several cores (``workers > 1``): each worker process draws and differentiates its own
``batch_size / workers`` windows with one intra-op thread, and the workers average their gradients
(``torch.distributed``, gloo) before every identical AdamW step, so the optimisation is that of the whole batch.
The networks are small and their operations tiny: a second intra-op thread bought a 2-core machine little (one
thread: about 30 s an epoch; two: about 26 s); two single-threaded workers were 9 % faster than two threads over a
whole run there, and they grow with the cores (see ``docs/motion_prior.md``).
The calling process is worker 0 (validation, progress, the result); the others are spawned and build their own
body model (:mod:`humancal.prior.workers`).

Every random choice (windows, augmentation, initialisation, the reparameterisation noise) derives from
``config.seed``: the same clips, config and worker count give the same weights, bit for bit, on the same machine
and thread count. The global torch random state is left untouched. One worker draws exactly the windows and noise
it drew before workers existed (the shipped weights were trained so).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

from humancal.body.rest import RestSkeleton
from humancal.lifter.evaluate import HELD_OUT_CMU_SUBJECTS
from humancal.prior.config import PriorConfig
from humancal.prior.data import MotionClips, MotionWindows, clips_from_retargeted, sample_windows
from humancal.prior.losses import pose_keypoints_m, prior_losses
from humancal.prior.model import MotionVAE, pose6d_to_rotmats, rotmats_to_pose6d
from humancal.prior.workers import EpochReport, average_over_workers, optimise_with_workers
from humancal.retarget.threads import torch_threads

__all__ = ["TrainedPrior", "clip_rest_skeletons", "reconstruction_mpjpe_mm", "train_motion_prior"]

logger = logging.getLogger(__name__)

ProgressCallback = Callable[[dict[str, Any]], None]

_EVAL_CHUNK = 256
_LOSS_NAMES = ("total", "pose6d", "keypoints_m2", "kl", "local_linear", "keypoint_error_m")


@dataclass(frozen=True)
class TrainedPrior:
    """The result of :func:`train_motion_prior`.

    Attributes:
        model: the trained :class:`MotionVAE` (in eval mode).
        config: the configuration it was trained with.
        history: one record per epoch, epoch 0 being the untrained model: ``epoch``, ``steps``, ``lr``,
            ``kl_weight``, the epoch means of the training terms ``train_loss``, ``train_pose6d``,
            ``train_keypoints_m2``, ``train_kl``, ``train_local_linear``, ``train_keypoint_error_mm``
            (NaN for epoch 0), the held-out ``val_mpjpe_mm`` and ``val_kl``, and ``elapsed_s``.
        train_seconds: wall time of the whole training (validation included), seconds.
        train_cpu_seconds: CPU time of this process over the training (all threads summed; with several workers,
            worker 0's alone), seconds; on a shared machine it tells the work apart from the waiting.
        train_subjects: subjects of the training clips.
        held_out_subjects: subjects of the held-out clips.
        held_out: final held-out figures: ``mpjpe_mm`` (posterior-mean reconstruction), ``kl``, ``windows``.
        data_digest: :meth:`MotionClips.digest` of all clips (training and held-out).
        num_train_frames: frames of the training clips.
    """

    model: MotionVAE
    config: PriorConfig
    history: list[dict[str, Any]]
    train_seconds: float
    train_subjects: tuple[str, ...]
    held_out_subjects: tuple[str, ...]
    held_out: dict[str, float] = field(default_factory=dict)
    data_digest: str = ""
    num_train_frames: int = 0
    train_cpu_seconds: float = 0.0


def _learning_rate(config: PriorConfig, step: int, total_steps: int) -> float:
    progress = min(step / max(total_steps, 1), 1.0)
    floor = config.learning_rate * config.final_lr_factor
    return floor + 0.5 * (config.learning_rate - floor) * (1.0 + math.cos(math.pi * progress))


def _kl_weight(config: PriorConfig, step: int) -> float:
    ramp = config.kl_anneal_epochs * config.steps_per_epoch
    return config.weight_kl if ramp == 0 else config.weight_kl * min(step / ramp, 1.0)


def clip_rest_skeletons(body_model, clips: MotionClips) -> RestSkeleton:
    """Rest skeletons of the clips' bodies, one per clip (no gradient).

    Raises:
        ValueError: phenotypes outside [0, 1] or non-finite (from ``BodyModel.rest_skeleton``).
    """
    with torch.no_grad():
        phenotypes = torch.as_tensor(clips.phenotypes, dtype=body_model.dtype, device=body_model.device)
        return body_model.rest_skeleton(phenotypes).detach()


@torch.no_grad()
def reconstruction_mpjpe_mm(
    model: MotionVAE, windows: MotionWindows, rest: RestSkeleton, body_model
) -> dict[str, float]:
    """Held-out reconstruction from the posterior mean: MPJPE of the 23 keypoints and the KL.

    Args:
        model: the prior.
        windows: (B, T, 21, 3, 3) windows and the clip of each.
        rest: rest skeletons indexed by ``windows.clip_index`` (:func:`clip_rest_skeletons`).
        body_model: the ``humancal.body.BodyModel``.

    Returns:
        ``mpjpe_mm`` (mean Euclidean error over windows, frames and the 23 keypoints, root at the origin,
        identity root rotation), ``kl`` (mean per coordinate) and ``windows``.
    """
    was_training = model.training
    model.eval()
    errors, kls = [], []
    dtype = body_model.dtype
    for first in range(0, len(windows.clip_index), _EVAL_CHUNK):
        rows = slice(first, first + _EVAL_CHUNK)
        target_R = windows.bone_rotmats[rows].to(dtype)
        clip_rest = rest.select(torch.as_tensor(windows.clip_index[rows]))
        mu, logvar = model.encode(rotmats_to_pose6d(target_R).float())
        pred_R = pose6d_to_rotmats(model.decode(mu)).to(dtype)
        target = pose_keypoints_m(body_model, clip_rest, target_R)
        pred = pose_keypoints_m(body_model, clip_rest, pred_R)
        errors.append(torch.linalg.vector_norm(pred - target, dim=-1).flatten(1).mean(dim=1))
        kls.append((0.5 * (mu.square() + logvar.exp() - 1.0 - logvar)).flatten(1).mean(dim=1))
    model.train(was_training)
    return {
        "mpjpe_mm": 1000.0 * float(torch.cat(errors).mean()),
        "kl": float(torch.cat(kls).mean()),
        "windows": float(len(windows.clip_index)),
    }


@dataclass(frozen=True)
class _Clips:
    """The clips of a run: all of them, and their split into training and held-out clips (whole subjects)."""

    all: MotionClips
    train: MotionClips
    held_out: MotionClips


@dataclass(frozen=True)
class _HeldOutWindows:
    """The fixed held-out windows scored after every epoch (plain: speed 1, forward, not mirrored).

    Attributes:
        windows: (B, T, 21, 3, 3) windows of the held-out clips and the clip of each.
        rest: rest skeletons of the held-out clips (:func:`clip_rest_skeletons`).
    """

    windows: MotionWindows
    rest: RestSkeleton


def _checked_arguments(config: PriorConfig | None, workers: int, threads: int | None) -> tuple[PriorConfig, int | None]:
    """The run's configuration (None: :meth:`PriorConfig.default`) and the torch threads of each worker.

    Raises:
        ValueError: not a :class:`PriorConfig`, a bad worker or thread count, or ``workers > 1`` while this process
            already has a ``torch.distributed`` group.
    """
    config = PriorConfig.default() if config is None else config
    if not isinstance(config, PriorConfig):
        raise ValueError(f"config must be a PriorConfig, got {type(config).__name__}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1 or config.batch_size % workers:
        raise ValueError(f"workers={workers!r} must be a positive integer dividing PriorConfig.batch_size="
                         f"{config.batch_size}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads={threads!r} must be a positive integer or None")
    if workers > 1 and dist.is_available() and dist.is_initialized():
        raise ValueError("workers > 1 needs a process without a torch.distributed group; this one has one")
    return config, threads if threads is not None else (None if workers == 1 else 1)


def _split_clips(clips: Sequence | MotionClips, held_out_subjects: Sequence[str]) -> _Clips:
    """The clips as :class:`MotionClips`, whole ``held_out_subjects`` held out of training.

    Raises:
        ValueError: malformed clips, or the split leaves no training or no held-out clip.
    """
    all_clips = clips if isinstance(clips, MotionClips) else clips_from_retargeted(clips)
    train_clips, val_clips = all_clips.split_subjects(held_out_subjects)
    return _Clips(all=all_clips, train=train_clips, held_out=val_clips)


def _held_out_windows(val_clips: MotionClips, config: PriorConfig, body_model) -> _HeldOutWindows:
    """``config.validation_windows`` plain windows of the held-out clips, drawn from the first stream of
    ``config.seed``, and the rest skeletons of their clips."""
    seeds = np.random.SeedSequence(config.seed).spawn(config.epochs + 1)
    windows = sample_windows(val_clips, config.validation_windows, config, np.random.default_rng(seeds[0]), False)
    return _HeldOutWindows(windows=windows, rest=clip_rest_skeletons(body_model, val_clips))


def _epoch_reporter(
    config: PriorConfig, held_out: _HeldOutWindows, body_model, start: float, history: list[dict[str, Any]],
    progress: ProgressCallback | None,
) -> EpochReport:
    """Worker 0's end-of-epoch report: it scores the model on ``held_out``, appends the record to ``history`` (see
    :class:`TrainedPrior`), logs it at INFO and passes it to ``progress``. ``start``: ``time.perf_counter()`` at the
    start of the training."""

    def report(epoch: int, step: int, lr: float, terms: dict[str, list[float]], model: MotionVAE) -> None:
        scores = reconstruction_mpjpe_mm(model, held_out.windows, held_out.rest, body_model)
        mean = {name: float(np.mean(values)) if values else float("nan") for name, values in terms.items()}
        record = {
            "epoch": epoch,
            "steps": step,
            "lr": lr,
            "kl_weight": _kl_weight(config, step),
            "train_loss": mean["total"],
            "train_pose6d": mean["pose6d"],
            "train_keypoints_m2": mean["keypoints_m2"],
            "train_kl": mean["kl"],
            "train_local_linear": mean["local_linear"],
            "train_keypoint_error_mm": 1000.0 * mean["keypoint_error_m"],
            "val_mpjpe_mm": scores["mpjpe_mm"],
            "val_kl": scores["kl"],
            "elapsed_s": time.perf_counter() - start,
        }
        history.append(record)
        logger.info(
            "epoch %d: loss %.4f, train keypoints %.1f mm, held-out MPJPE %.1f mm, KL %.3f (%.0f s)",
            epoch, record["train_loss"], record["train_keypoint_error_mm"], record["val_mpjpe_mm"],
            record["val_kl"], record["elapsed_s"],
        )
        if progress is not None:
            progress({"kind": "epoch", **record})

    return report


def train_motion_prior(
    clips: Sequence | MotionClips,
    config: PriorConfig | None,
    body_model,
    progress: ProgressCallback | None = None,
    held_out_subjects: Sequence[str] = HELD_OUT_CMU_SUBJECTS,
    workers: int = 1,
    threads: int | None = None,
) -> TrainedPrior:
    """Train a motion prior.

    Args:
        clips: retargeted clips (``humancal.retarget.RetargetedClip``, e.g. from
            ``motions_table_to_clips(mocap_clips table)``) or a :class:`MotionClips`.
        config: the run configuration (None: :meth:`PriorConfig.default`).
        body_model: the ``humancal.body.BodyModel`` of the keypoint loss and the held-out MPJPE.
        progress: called after every epoch with ``{"kind": "epoch"}`` plus the history record (epoch 0 first).
            Records are also logged at INFO.
        held_out_subjects: subjects whose clips are held out of training (whole subjects) and score each epoch.
        workers: processes sharing each step's batch (data parallel, module docstring); 1 trains here alone.
            ``config.batch_size`` must be a multiple of it. The other workers are started with the "spawn"
            method, so a script calling this at its top level needs Python's ``if __name__ == "__main__":`` guard.
        threads: torch intra-op threads of each worker; None: the caller's setting with one worker, 1 with more.

    Returns:
        The :class:`TrainedPrior`.

    Raises:
        ValueError: malformed clips, holding out ``held_out_subjects`` leaves no training or no held-out clip, a bad
            worker or thread count, or ``workers > 1`` while this process already has a ``torch.distributed`` group.
        RuntimeError: a worker process failed (its error is in the message).
    """
    config, threads = _checked_arguments(config, workers, threads)
    clips = _split_clips(clips, held_out_subjects)
    start, start_cpu = time.perf_counter(), time.process_time()
    held_out = _held_out_windows(clips.held_out, config, body_model)
    history: list[dict[str, Any]] = []
    report = _epoch_reporter(config, held_out, body_model, start, history, progress)
    with torch_threads(threads):
        if workers == 1:
            model = _optimise(clips.train, config, body_model, 0, 1, report)
        else:
            model = optimise_with_workers(_optimise, clips.train, config, body_model, workers, threads, report)
        final = reconstruction_mpjpe_mm(model, held_out.windows, held_out.rest, body_model)
    return TrainedPrior(
        model=model,
        config=config,
        history=history,
        train_seconds=time.perf_counter() - start,
        train_subjects=tuple(sorted(set(clips.train.subjects))),
        held_out_subjects=tuple(sorted(set(clips.held_out.subjects))),
        held_out=final,
        data_digest=clips.all.digest(),
        num_train_frames=int(clips.train.starts[-1]),
        train_cpu_seconds=time.process_time() - start_cpu,
    )


def _optimise(
    train_clips: MotionClips, config: PriorConfig, body_model, rank: int, workers: int,
    report: EpochReport | None,
) -> MotionVAE:
    """The optimisation loop of one worker (``rank`` of ``workers``; the only one when ``workers`` is 1).

    Every worker builds the same initial model and takes the same steps with the gradients averaged over the
    workers; each draws its own ``batch_size / workers`` windows and reparameterisation noise. ``report`` (worker
    0 only) scores the model after every epoch.

    Returns:
        The trained model (eval mode).
    """
    train_rest = clip_rest_skeletons(body_model, train_clips)
    total_steps = config.epochs * config.steps_per_epoch
    batch = config.batch_size // workers
    weights = {
        "weight_6d": config.weight_6d,
        "weight_keypoints": config.weight_keypoints,
        "weight_local_linear": config.local_linear_weight,
    }
    if workers == 1:  # the streams of the single-process trainer the shipped weights came from
        epoch_seeds = np.random.SeedSequence(config.seed).spawn(config.epochs + 1)
        noise_seed = config.seed + 1
    else:
        epoch_seeds = [np.random.SeedSequence(config.seed, spawn_key=(epoch, rank)) for epoch in
                       range(config.epochs + 1)]
        noise_seed = int(np.random.SeedSequence(config.seed, spawn_key=(config.epochs + 1, rank)).generate_state(1)[0])
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        model = MotionVAE(config)
        noise = torch.Generator().manual_seed(noise_seed)
        optimizer = torch.optim.AdamW(model.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay)
        if report is not None:
            report(0, 0, config.learning_rate, {name: [] for name in _LOSS_NAMES}, model)
        step, lr = 0, config.learning_rate
        for epoch in range(1, config.epochs + 1):
            rng = np.random.default_rng(epoch_seeds[epoch])
            terms: dict[str, list[float]] = {name: [] for name in _LOSS_NAMES}
            model.train()
            for _ in range(config.steps_per_epoch):
                windows = sample_windows(train_clips, batch, config, rng)
                target_R = windows.bone_rotmats.to(body_model.dtype)
                clip_rest = train_rest.select(torch.as_tensor(windows.clip_index))
                with torch.no_grad():
                    target_keypoints = pose_keypoints_m(body_model, clip_rest, target_R).float()
                target6d = rotmats_to_pose6d(windows.bone_rotmats.float())
                lr = _learning_rate(config, step, total_steps)
                for group in optimizer.param_groups:
                    group["lr"] = lr
                output = model(target6d, sample=True, generator=noise)
                losses = prior_losses(
                    output, target6d, target_keypoints, body_model, clip_rest,
                    weight_kl=_kl_weight(config, step), **weights,
                )
                optimizer.zero_grad(set_to_none=True)
                losses["total"].backward()
                values = torch.stack([losses[name].detach() for name in _LOSS_NAMES])
                if workers > 1:
                    average_over_workers([p.grad for p in model.parameters()] + [values], workers)
                optimizer.step()
                step += 1
                for name, value in zip(_LOSS_NAMES, values.tolist()):
                    terms[name].append(value)
            if report is not None:
                report(epoch, step, lr, terms, model)
        model.eval()
    return model
