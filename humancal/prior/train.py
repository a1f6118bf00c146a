"""Training of the motion prior on retargeted mocap clips, with whole subjects held out.

Every optimisation step draws a fresh batch of augmented windows from the training clips
(:func:`humancal.prior.data.sample_windows`), encodes them, decodes a sampled latent and minimises the loss of
:mod:`humancal.prior.losses` (the KL weight grows linearly over the first ``kl_anneal_epochs`` epochs). AdamW
with a per-step cosine decay of the learning rate. After every epoch the model reconstructs fixed held-out
windows (plain: speed 1, forward, not mirrored) from their posterior means and is scored by the MPJPE of the 23
canonical keypoints (root at the origin, identity root rotation; :func:`humancal.prior.losses.pose_keypoints_m`).

Every random choice (windows, augmentation, initialisation, the reparameterisation noise) derives from
``config.seed``: the same clips and config give the same weights, bit for bit, on the same machine and thread
count. The global torch random state is left untouched.
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

from humancal.body.rest import RestSkeleton
from humancal.lifter.evaluate import HELD_OUT_CMU_SUBJECTS
from humancal.prior.config import PriorConfig
from humancal.prior.data import MotionClips, MotionWindows, clips_from_retargeted, sample_windows
from humancal.prior.losses import pose_keypoints_m, prior_losses
from humancal.prior.model import MotionVAE, pose6d_to_rotmats, rotmats_to_pose6d

__all__ = ["TrainedPrior", "train_motion_prior", "reconstruction_mpjpe_mm", "clip_rest_skeletons"]

logger = logging.getLogger(__name__)

ProgressCallback = Callable[[dict[str, Any]], None]

_EVAL_CHUNK = 256


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
        train_cpu_seconds: CPU time of this process over the training (all threads summed), seconds; on a
            shared machine it tells the work apart from the waiting.
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


def train_motion_prior(
    clips: Sequence | MotionClips,
    config: PriorConfig | None,
    body_model,
    progress: ProgressCallback | None = None,
    held_out_subjects: Sequence[str] = HELD_OUT_CMU_SUBJECTS,
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

    Returns:
        The :class:`TrainedPrior`.

    Raises:
        ValueError: malformed clips, or holding out ``held_out_subjects`` leaves no training or no held-out clip.
    """
    config = PriorConfig.default() if config is None else config
    if not isinstance(config, PriorConfig):
        raise ValueError(f"config must be a PriorConfig, got {type(config).__name__}")
    all_clips = clips if isinstance(clips, MotionClips) else clips_from_retargeted(clips)
    train_clips, val_clips = all_clips.split_subjects(held_out_subjects)
    start, start_cpu = time.perf_counter(), time.process_time()
    seeds = np.random.SeedSequence(config.seed).spawn(config.epochs + 1)
    val_windows = sample_windows(val_clips, config.validation_windows, config, np.random.default_rng(seeds[0]), False)
    train_rest = clip_rest_skeletons(body_model, train_clips)
    val_rest = clip_rest_skeletons(body_model, val_clips)
    total_steps = config.epochs * config.steps_per_epoch
    weights = {
        "weight_6d": config.weight_6d,
        "weight_keypoints": config.weight_keypoints,
        "weight_local_linear": config.local_linear_weight,
    }
    history: list[dict[str, Any]] = []

    def report(epoch: int, step: int, lr: float, terms: dict[str, list[float]], model: MotionVAE) -> None:
        scores = reconstruction_mpjpe_mm(model, val_windows, val_rest, body_model)
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

    names = ("total", "pose6d", "keypoints_m2", "kl", "local_linear", "keypoint_error_m")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        model = MotionVAE(config)
        noise = torch.Generator().manual_seed(config.seed + 1)
        optimizer = torch.optim.AdamW(model.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay)
        report(0, 0, config.learning_rate, {name: [] for name in names}, model)
        step, lr = 0, config.learning_rate
        for epoch in range(1, config.epochs + 1):
            rng = np.random.default_rng(seeds[epoch])
            terms: dict[str, list[float]] = {name: [] for name in names}
            model.train()
            for _ in range(config.steps_per_epoch):
                windows = sample_windows(train_clips, config.batch_size, config, rng)
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
                optimizer.step()
                step += 1
                for name in names:
                    terms[name].append(float(losses[name].detach()))
            report(epoch, step, lr, terms, model)
        model.eval()
    final = reconstruction_mpjpe_mm(model, val_windows, val_rest, body_model)
    return TrainedPrior(
        model=model,
        config=config,
        history=history,
        train_seconds=time.perf_counter() - start,
        train_subjects=tuple(sorted(set(train_clips.subjects))),
        held_out_subjects=tuple(sorted(set(val_clips.subjects))),
        held_out=final,
        data_digest=all_clips.digest(),
        num_train_frames=int(train_clips.starts[-1]),
        train_cpu_seconds=time.process_time() - start_cpu,
    )
