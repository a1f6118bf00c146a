"""Per-subject shape fit: anny phenotypes and the correspondence offsets, from frames of all of a subject's clips.

Three stages, all deterministic:

1. **Bone lengths.** Phenotypes (a sigmoid onto ``[phenotype_low, phenotype_high]``) fitted by L-BFGS to the
   lengths of the segments whose ends are defined alike in both rigs (consecutive bone-head links without
   offsets: for the Daz table the shins and forearms), plus the phenotype prior. This sets the overall size.
2. **Poses and offsets.** From the analytic pose start of the selected frames (:mod:`humancal.retarget.init`,
   offsets zero), the poses and the offsets together by Gauss-Newton with a Schur complement
   (:mod:`humancal.retarget.offsets`, which explains why they must be solved together).
3. **Shape.** ``shape_rounds`` alternations of an L-BFGS solve over phenotypes and offsets with the poses fixed
   (autograd through anny's rest skeleton) and the joint poses + offsets solve of stage 2, warm-started. The
   objective is the pose objective (no smoothness: the frames are not consecutive) plus the offset, phenotype and
   pelvis-tilt priors; the positions of all mapped joints over many poses decide every bone length here.

The selected poses are then dropped; shape and offsets are frozen for the subject's clips.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from humancal.body import PHENOTYPE_NAMES, BodyModel
from humancal.mocap import MocapClip
from humancal.retarget.config import RetargetConfig
from humancal.retarget.correspondence import ResolvedLinks, mocap_targets_m, resolve_links
from humancal.retarget.init import analytic_pose_init
from humancal.retarget.priors import PoseWeights
from humancal.retarget.offsets import fit_poses_and_offsets
from humancal.retarget.points import PointModel
from humancal.retarget.pose import pose_objective, run_lbfgs
from humancal.retarget.threads import torch_threads

__all__ = ["SubjectFit", "fit_subject", "fit_subject_phenotypes", "length_segments", "select_frames"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SubjectFit:
    """The frozen per-subject part of a retarget.

    Attributes:
        subject: subject id.
        phenotypes: (6,) float64 in [0, 1], ``PHENOTYPE_NAMES`` order.
        offsets_m: (M, 3) float64 learned offsets of the mapped points, metres, in the reference-pose axes of each
            link's carrier bone (zero where the table learns none).
        mapped_joint_names: (M,) mocap joint names of the correspondence.
        residual_mm: median distance of the mapped points to the mocap joints over the frames of the fit, mm.
        frames_used: number of frames the fit used.
    """

    subject: str
    phenotypes: np.ndarray
    offsets_m: np.ndarray
    mapped_joint_names: tuple[str, ...]
    residual_mm: float
    frames_used: int


def _as_clips(clips: Sequence[MocapClip] | MocapClip) -> list[MocapClip]:
    clips = [clips] if isinstance(clips, MocapClip) else list(clips)
    if not clips:
        raise ValueError("no clips given")
    for clip in clips:
        if not isinstance(clip, MocapClip):
            raise ValueError(f"expected humancal.mocap.MocapClip objects, got {type(clip).__name__}")
    return clips


def select_frames(frame_counts: Sequence[int], num_frames: int) -> list[np.ndarray]:
    """Evenly spread ``num_frames`` frame indices over clips, in proportion to their lengths (deterministic).

    Args:
        frame_counts: frames of each clip.
        num_frames: total frames wanted (every clip gets at least one; no clip more than it has).

    Returns:
        Per clip, the sorted unique frame indices.
    """
    counts = np.asarray(frame_counts, dtype=np.int64)
    share = np.maximum(1, np.round(num_frames * counts / counts.sum()).astype(np.int64))
    share = np.minimum(share, counts)
    return [np.unique(np.round(np.linspace(0, n - 1, k)).astype(np.int64)) for n, k in zip(counts, share)]


def length_segments(resolved: ResolvedLinks, posed_parents: Sequence[int]) -> list[tuple[int, int]]:
    """Pairs (child link, parent link) of bone-head links without offsets on consecutive posed bones.

    Their distance is a bone length in both rigs. For :data:`DAZ_CMU_LINKS`: knee-ankle and elbow-wrist.
    """
    plain = {
        int(resolved.anchor_bone[m]): m
        for m in range(resolved.num_points)
        if resolved.anchor_bone[m] >= 0 and not resolved.learn_offset[m]
    }
    return [(m, plain[posed_parents[b]]) for b, m in plain.items() if b > 0 and posed_parents[b] in plain]


class _PhenotypeMap:
    """Phenotypes as ``low + (high - low) * sigmoid(z)``."""

    def __init__(self, config: RetargetConfig, dtype: torch.dtype) -> None:
        self.low = torch.tensor(config.phenotype_low, dtype=dtype)
        self.span = torch.tensor(config.phenotype_high, dtype=dtype) - self.low
        self.init = torch.tensor(config.phenotype_init, dtype=dtype)

    def logits(self, phenotypes: Tensor) -> Tensor:
        unit = ((phenotypes - self.low) / self.span).clamp(1e-3, 1 - 1e-3)
        return torch.log(unit / (1 - unit))

    def __call__(self, logits: Tensor) -> Tensor:
        return self.low + self.span * torch.sigmoid(logits)


def _subject_targets(clips: list[MocapClip], resolved: ResolvedLinks, config: RetargetConfig) -> np.ndarray:
    resampled = [clip if clip.fps == config.fps else clip.resample(config.fps) for clip in clips]
    picks = select_frames([c.frames for c in resampled], config.shape_frames)
    return np.concatenate([mocap_targets_m(c, resolved.mocap_joints)[p] for c, p in zip(resampled, picks)])


def check_phenotypes(phenotypes: np.ndarray) -> np.ndarray:
    """``phenotypes`` as a new (6,) float64 array, checked to be finite and within [0, 1] (ValueError otherwise)."""
    phenotypes = np.array(phenotypes, dtype=np.float64)
    if phenotypes.shape != (len(PHENOTYPE_NAMES),):
        raise ValueError(f"phenotypes must have shape (6,) ({', '.join(PHENOTYPE_NAMES)}), got {phenotypes.shape}")
    if not np.isfinite(phenotypes).all() or (phenotypes < 0).any() or (phenotypes > 1).any():
        raise ValueError(f"phenotypes must be finite and within [0, 1], got {phenotypes.tolist()}")
    return phenotypes


def fit_subject(
    clips: Sequence[MocapClip] | MocapClip,
    body: BodyModel,
    config: RetargetConfig = RetargetConfig(),
    phenotypes: np.ndarray | None = None,
) -> SubjectFit:
    """Fit one subject's phenotypes and correspondence offsets over frames of all its clips.

    Args:
        clips: the subject's clips (any frame rate; resampled to ``config.fps``), all with the same ``subject``.
        body: the body model.
        config: the retarget settings.
        phenotypes: (6,) known phenotypes in [0, 1]: then only the offsets are fitted (shape frozen).

    Returns:
        The :class:`SubjectFit`.

    Raises:
        ValueError: no clips, clips of several subjects, clips lacking mapped joints or holding non-finite
            positions, or phenotypes of the wrong shape or outside [0, 1].
    """
    with torch_threads(config.torch_threads):
        return _fit_subject(_as_clips(clips), body, config, phenotypes)


def _fit_subject(
    clips: list[MocapClip], body: BodyModel, config: RetargetConfig, phenotypes: np.ndarray | None
) -> SubjectFit:
    subjects = sorted({clip.subject for clip in clips})
    if len(subjects) > 1:
        raise ValueError(f"fit_subject needs the clips of one subject, got subjects {subjects}")
    frozen = phenotypes is not None
    dtype = body.dtype
    resolved = resolve_links(config.links, body.posed_bones, body.posed_parents)
    points = PointModel(body, resolved)
    targets = torch.as_tensor(_subject_targets(clips, resolved, config), dtype=dtype)
    mapping = _PhenotypeMap(config, dtype)
    if frozen:
        phenotypes = check_phenotypes(phenotypes)
        fixed = torch.as_tensor(phenotypes, dtype=dtype)
        logits = mapping.logits(fixed)  # unused: the shape stays ``fixed``
    else:
        logits = _fit_lengths(body, resolved, targets, mapping, mapping.logits(mapping.init), config)

    def phenotypes_of(z: Tensor) -> Tensor:
        return fixed if frozen else mapping(z)

    with torch.no_grad():
        rest = body.rest_skeleton(phenotypes_of(logits)[None])
    # Stage 2: poses of the selected frames from the analytic start, then poses and offsets together.
    f64 = torch.float64
    coordinates = torch.zeros(points.offset_basis(rest, f64).shape[1], dtype=f64)
    prior_weights = points.offset_prior_weights(config.offset_prior_weight, config.free_offset_prior_weight)
    start_offsets = torch.zeros(resolved.num_points, 3, dtype=f64)
    start = points.coefficients(rest, start_offsets)
    # The analytic start only: a pose fit with the offsets still zero would turn the pelvis to fit its rig points
    # as they are (a median 108 deg on CMU subject 02), a start the joint solve cannot always undo.
    rotmats, translation = analytic_pose_init(points, start, targets.to(f64), config.init_child_weight)
    pose_weights = PoseWeights.from_config(config, points, start, smooth=False, shape_fit=True)
    rotmats, translation, coordinates, total = fit_poses_and_offsets(
        points, rest, rotmats, translation, coordinates, targets, pose_weights,
        prior_weights, config.joint_iterations,
    )
    # Stage 3: shape and offsets (L-BFGS, poses fixed), then poses and offsets together, alternately.
    for _ in range(0 if frozen else config.shape_rounds):
        logits, coordinates = _fit_shape_and_offsets(
            body, points, mapping, logits, coordinates, rotmats.to(dtype), translation.to(dtype), targets, config
        )
        with torch.no_grad():
            rest = body.rest_skeleton(phenotypes_of(logits)[None])
        pose_weights = PoseWeights.from_config(
            config, points, points.coefficients(rest, start_offsets), smooth=False, shape_fit=True
        )
        rotmats, translation, coordinates, total = fit_poses_and_offsets(
            points, rest, rotmats, translation, coordinates, targets, pose_weights,
            prior_weights, config.joint_iterations,
        )
    with torch.no_grad():
        offsets = (points.offset_basis(rest, f64) @ coordinates).reshape(-1, 3)
        predicted = points.points(points.coefficients(rest, offsets), rotmats, translation)
        residual_mm = float((predicted - targets.to(f64)).norm(dim=-1).median()) * 1000.0
    final = torch.as_tensor(phenotypes, dtype=torch.float64) if frozen else mapping(logits).to(torch.float64)
    logger.info(
        "subject %s: %s fitted over %d frames of %d clip(s), objective %.3g m^2 per frame, median residual %.1f mm; "
        "phenotypes %s",
        subjects[0], "offsets" if frozen else "shape and offsets", targets.shape[0], len(clips),
        total / targets.shape[0], residual_mm, np.round(final.numpy(), 3).tolist(),
    )
    return SubjectFit(
        subject=subjects[0],
        phenotypes=final.numpy().copy(),
        offsets_m=offsets.numpy().copy(),
        mapped_joint_names=resolved.mocap_joints,
        residual_mm=residual_mm,
        frames_used=int(targets.shape[0]),
    )


def _fit_shape_and_offsets(
    body: BodyModel,
    points: PointModel,
    mapping: _PhenotypeMap,
    logits: Tensor,
    coordinates: Tensor,
    rotmats: Tensor,
    translation: Tensor,
    targets: Tensor,
    config: RetargetConfig,
) -> tuple[Tensor, Tensor]:
    """One L-BFGS solve over phenotype logits and offset coordinates, with the poses fixed (autograd through anny)."""
    dtype = body.dtype
    z = logits.clone().requires_grad_(True)
    phi = coordinates.to(dtype).clone().requires_grad_(True)
    prior_weights = points.offset_prior_weights(config.offset_prior_weight, config.free_offset_prior_weight, dtype)

    def loss_fn() -> Tensor:
        rest = body.rest_skeleton(mapping(z)[None])
        offsets = (points.offset_basis(rest, dtype) @ phi).reshape(-1, 3)
        loss = pose_objective(points, points.coefficients(rest, offsets), rotmats, translation, targets, config)
        loss = loss + (prior_weights * phi**2).sum()
        return loss + config.phenotype_prior_weight * ((mapping(z) - mapping.init) ** 2).sum()

    run_lbfgs([z, phi], loss_fn, config.shape_iterations, config.lbfgs_history)
    return z.detach(), phi.detach().to(torch.float64)


def _fit_lengths(
    body: BodyModel,
    resolved: ResolvedLinks,
    targets: Tensor,
    mapping: _PhenotypeMap,
    logits: Tensor,
    config: RetargetConfig,
) -> Tensor:
    """Stage 1: phenotype logits fitted to the lengths of :func:`length_segments` (median over frames)."""
    segments = length_segments(resolved, body.posed_parents)
    if not segments:
        logger.info("no offset-free consecutive bone-head links: bone-length stage skipped")
        return logits
    child = [m for m, _ in segments]
    parent = [n for _, n in segments]
    lengths_m = (targets[:, child] - targets[:, parent]).norm(dim=-1).median(dim=0).values
    child_bone = torch.as_tensor(resolved.anchor_bone[child])
    parent_bone = torch.as_tensor(resolved.anchor_bone[parent])
    z = logits.clone().requires_grad_(True)

    def loss_fn() -> Tensor:
        phen = mapping(z)
        heads = body.rest_skeleton(phen[None]).bone_heads_m[0]
        model_m = (heads[child_bone] - heads[parent_bone]).norm(dim=-1)
        prior = config.phenotype_prior_weight * ((phen - mapping.init) ** 2).sum()
        return ((model_m - lengths_m) ** 2).sum() + prior

    run_lbfgs([z], loss_fn, config.length_iterations, config.lbfgs_history)
    return z.detach()


def fit_subject_phenotypes(
    clips: Sequence[MocapClip] | MocapClip, body: BodyModel, config: RetargetConfig = RetargetConfig()
) -> np.ndarray:
    """The phenotypes of one subject (see :func:`fit_subject`, which also returns the offsets).

    Returns:
        (6,) float64 in [0, 1], ``PHENOTYPE_NAMES`` order.
    """
    return fit_subject(clips, body, config).phenotypes
