"""Bodies and motions of every person fitted to the associated detections, cameras held fixed (the paper's III-E).

Variables per person (``humancal.fitting.problem``): the body shape (anny phenotypes, through a logistic map so
they stay in [0, 1]), the root orientation (6D) and translation of every frame, and the body pose of every frame:
the motion prior's latent codes (T x 32, decoder frozen) or, for the no-prior baseline, the 21 bones' 6D rotations.

Variables per camera (``BodyFitConfig.cameras``, ``humancal.fitting.cameras``): none (``fixed``), the extrinsics
(``ext``), or the focal length and the extrinsics (``int_ext``: fully self-calibrated).

Objective (``BodyFitConfig`` documents the units): a confidence-weighted Geman-McClure reprojection term of the
23 canonical keypoints in every view, through the shared camera model (``humancal.camera.projection``); the
latent prior ``mean(z^2)``; the local-linear term ``mean((z[t+1] - 2 z[t] + z[t-1])^2)``; a shape prior; a root
smoothness term; for long sequences cut into windows (``humancal.prior.windows``), a seam term; the
interpenetration of different people (``humancal.fitting.contact``); and, when the cameras move, a weak tie of
each camera to its initial value.

Schedule: when the cameras move, they first take a bundle adjustment on the triangulated joints as free points
(``BodyFitConfig.bundle_start``, :func:`humancal.fitting.joint_bundle.bundle_adjust_on_joints`: the ``separate``
baseline's cameras), and the joint refinement starts from there (chosen on synthetic scenes whose detector has its own
definition of the joints, where a body cannot explain what free points can; ``docs/refinement.md``). The root of
each frame starts from a rigid alignment of the average body onto the triangulated
joints (``skeletons3d``); then three stages run on all people and all windows at once:

1. ``fit3d``: shape, root and body pose on the triangulated joints, by Adam (cheap and well conditioned, but
   thousands of nearly separable per-frame problems far from their solution, where one L-BFGS line search for
   all of them converged several times slower in the trials on synthetic scenes); the latents start at the
   prior's mean, z = 0 (``BodyFitConfig.latent_start``): a natural average pose, from which every person reached
   their pose sooner than from the encoding of the reference pose (arms out), which was lower in MPJPE in none of
   ten synthetic scenes. (Starting them from the encoding of a raw-angle inverse kinematics was tried and is
   worse: its poses are far from the prior's, and decode 85-90 mm away.)
2. ``cameras`` (when they move): the cameras on the 2D detections, the people held, by L-BFGS;
3. ``global``: root orientation and translation on the 2D detections, body and cameras held, by L-BFGS;
4. ``body``: every person's variables on the 2D detections, cameras held, by L-BFGS.

Stages 2-4 are the paper's three substages; they run ``rounds`` times in turn when the cameras move (once when
they are fixed). Holding the people while the cameras move (and the other way round) keeps the world frame where
the calibration put it: nothing can drift along the similarity that moves everything at once. At the end the floor
is put back at z = 0 (the median lowest sole point of the standing person-frames, as the calibration defines it).

Per-frame work runs on the body model's compact keypoint path; no mesh is built here.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from humancal.body import BodyModel
from humancal.calibration.types import FOOT_JOINTS
from humancal.camera import CameraRig
from humancal.fitting.cameras import camera_shift_px
from humancal.fitting.config import BodyFitConfig
from humancal.fitting.joint_bundle import bundle_adjust_on_joints
from humancal.fitting.motions import FittedMotions
from humancal.fitting.observations import BodyObservations, FittingInputError, unswap_left_right
from humancal.fitting.problem import INITIAL_PHENOTYPES, BodyFitProblem, run_stage
from humancal.fitting.schedule import half_rate_steps, stage_schedule
from humancal.lifter.pose_cues import standing_score
from humancal.prior.model import MotionVAE

__all__ = ["BodyFitResult", "fit_bodies", "INITIAL_PHENOTYPES", "STAGES"]

log = logging.getLogger(__name__)

STAGES = ("fit3d", "cameras", "global", "body")


@dataclass(frozen=True)
class BodyFitResult:
    """A body fit's output.

    Attributes:
        motions: the fitted people (``FittedMotions``).
        cameras: the cameras after the fit (the initial ones when ``BodyFitConfig.cameras`` is ``fixed``), in the
            same world as the motions.
        latents: (P, W, L, latent_dim) the fitted latent windows (prior fits), else None.
        stage_seconds: wall seconds of ``bundle`` (the bundle-adjusted start of moving cameras; 0 otherwise),
            ``prepare``, each stage of ``STAGES`` (summed over rounds), ``floor`` and ``total``.
        loss_terms: every term of the objective after the last stage (unweighted), and ``total`` (weighted).
        reprojection_error_px: mean pixel distance between the fitted keypoints and the detected ones, over every
            detected keypoint (score > 0) in front of its camera.
        warnings: people left out, and other things that did not stop the fit.
        round_shifts_px: per round of the substages run with moving cameras, how far its camera substage moved
            the cameras (mean reprojection shift of the people's keypoints, pixels; ``BodyFitConfig.round_stop_px``);
            empty with fixed cameras.
    """

    motions: FittedMotions
    cameras: CameraRig
    latents: np.ndarray | None
    stage_seconds: dict[str, float]
    loss_terms: dict[str, float]
    reprojection_error_px: float
    warnings: tuple[str, ...] = ()
    round_shifts_px: tuple[float, ...] = ()


def fit_bodies(
    body: BodyModel,
    observations: BodyObservations,
    rig: CameraRig,
    prior: MotionVAE | None,
    config: BodyFitConfig = BodyFitConfig(),
    *,
    fps: float = 30.0,
    warnings: tuple[str, ...] = (),
    progress: Callable[[str, int, float], None] | None = None,
) -> BodyFitResult:
    """Fit every person's shape and motion to their detections, and refine the cameras with them unless
    ``config.cameras`` is ``fixed`` (module docstring).

    Args:
        body: the body model (its dtype and device are the fit's).
        observations: the people's detections and triangulated joints (:func:`body_observations`).
        rig: the V initial cameras (held with ``cameras="fixed"``; with moving cameras, bundle-adjusted first when
            ``config.bundle_start``, and the adjustment's failure, if any, is one of the result's warnings).
        prior: the motion VAE whose latents are fitted (the default prior, or the per-frame variant, whose
            latents then get no local-linear term: the baseline without dynamics); None fits raw joint angles (the
            no-prior baseline). Its weights are not changed.
        config: weights and schedule.
        fps: the sequence's frame rate (stored with the motions).
        warnings: warnings of the inputs (e.g. people left out), passed through to the result.
        progress: called as ``progress(stage, evaluation, loss)`` after every objective evaluation.

    Returns:
        The :class:`BodyFitResult`.

    Raises:
        FittingInputError: observations of another number of views than the rig, or no detections at all.
    """
    if observations.num_views != len(rig):
        raise FittingInputError(f"body fit: detections of {observations.num_views} views, but {len(rig)} cameras")
    if not (observations.confidence > 0).any():
        raise FittingInputError("body fit: no detected keypoint with a score > 0 among the associated detections")
    start = time.perf_counter()
    start_cameras = _start_cameras(observations, rig, config, start)
    seconds = {"bundle": start_cameras.seconds}
    fit_warnings = list(warnings) + ([start_cameras.failure] if start_cameras.failure else [])
    prepare_start = time.perf_counter()
    setup = _set_up(body, observations, start_cameras.rig, prior, config)
    problem = setup.problem
    seconds["prepare"] = time.perf_counter() - prepare_start
    run = _run_schedule(body, setup, start_cameras.rig, config, progress)
    seconds.update(run.seconds)
    floor_start = time.perf_counter()
    floor_warning = _relevel_floor(problem)
    if floor_warning:
        fit_warnings.append(floor_warning)
    seconds["floor"] = time.perf_counter() - floor_start
    final = _final_state(problem)
    seconds["total"] = time.perf_counter() - start
    motions = _fitted_motions(final, problem, setup.observations, fps)
    latents = _to_numpy(problem.pose_params) if problem.latent else None
    cameras = problem.cameras.to_rig() if problem.cameras.moves else start_cameras.rig
    return BodyFitResult(motions, cameras, latents, seconds, run.terms, final.reprojection_px, tuple(fit_warnings),
                         run.round_shifts_px)


@dataclass(frozen=True)
class _CameraStart:
    """The cameras the people are first fitted with.

    Attributes:
        rig: the initial cameras, or their bundle adjustment on the triangulated joints.
        seconds: wall seconds from the fit's start to the end of that adjustment (0: none ran).
        failure: why the adjustment was undone, when it was (a warning of the fit).
    """

    rig: CameraRig
    seconds: float = 0.0
    failure: str | None = None


def _start_cameras(observations: BodyObservations, rig: CameraRig, config: BodyFitConfig,
                   start: float) -> _CameraStart:
    """Moving cameras (``config.cameras`` not ``fixed``) start from a bundle adjustment on the triangulated joints
    as free points when ``config.bundle_start`` (module docstring); other cameras start as given. ``start``: the
    fit's ``time.perf_counter()`` start."""
    if not (config.bundle_start and config.cameras != "fixed"):
        return _CameraStart(rig)
    bundle = bundle_adjust_on_joints(observations, rig, config, regime=config.cameras)
    seconds = time.perf_counter() - start
    if bundle.failure:
        log.warning("body fit: %s", bundle.failure)
    else:
        log.info("body fit: cameras bundle-adjusted on the triangulated joints in %.1f s", seconds)
    return _CameraStart(bundle.cameras, seconds, bundle.failure)


@dataclass(frozen=True)
class _Setup:
    """What the stages run on.

    Attributes:
        observations: the observations, with the detections whose left and right joints were swapped swapped back
            (``config.unswap_left_right``).
        prior: the motion prior in eval mode on the body model's dtype and device (None: the no-prior fit).
        problem: the variables and terms on every frame (a prior fit's body pose already its latent motion).
    """

    observations: BodyObservations
    prior: MotionVAE | None
    problem: BodyFitProblem


def _set_up(body: BodyModel, observations: BodyObservations, rig: CameraRig, prior: MotionVAE | None,
            config: BodyFitConfig) -> _Setup:
    """Undo the detector's left-right swaps against ``rig`` (when ``config.unswap_left_right``), bring the prior to
    the body model, and build the problem, its people at their rigid start (a prior fit's body pose as latents)."""
    if config.unswap_left_right:
        observations, swapped = unswap_left_right(observations, rig, min_error_px=config.noise_px)
        log.info("body fit: %d detection(s) with left and right swapped back", swapped)
    if prior is not None:
        prior = prior.to(dtype=body.dtype, device=body.device).eval()
    problem = BodyFitProblem(body, observations, rig, prior, config)
    problem.encode_pose()  # prior fits: from here the body pose is the latent motion
    return _Setup(observations, prior, problem)


@dataclass(frozen=True)
class _StagesRun:
    """The outcome of the stages.

    Attributes:
        terms: the last stage's terms, unweighted, and ``total`` (weighted); empty when no stage ran.
        seconds: wall seconds of each of ``STAGES`` (summed over rounds; fit3d's include its half-rate start).
        round_shifts_px: per round run, how far its camera substage moved the cameras
            (:func:`~humancal.fitting.cameras.camera_shift_px` over the people's keypoints), pixels.
    """

    terms: dict[str, float]
    seconds: dict[str, float]
    round_shifts_px: tuple[float, ...] = ()


def _run_schedule(body: BodyModel, setup: _Setup, rig: CameraRig, config: BodyFitConfig,
                progress: Callable[[str, int, float], None] | None) -> _StagesRun:
    """fit3d's half-rate start (on long sequences, :func:`~humancal.fitting.schedule.half_rate_steps`), then every
    stage of the schedule in turn on every frame (:func:`~humancal.fitting.schedule.stage_schedule`); the rounds end
    early after one whose cameras moved less than ``config.round_stop_px``."""
    problem = setup.problem
    seconds = dict.fromkeys(STAGES, 0.0)
    terms: dict[str, float] = {}
    shifts: list[float] = []
    half_rate = half_rate_steps(config, setup.observations.num_frames)
    if half_rate:
        stage_start = time.perf_counter()
        terms = _fit_half_rate(body, setup, rig, config, half_rate, progress)
        seconds["fit3d"] += time.perf_counter() - stage_start
        log.info("body fit, fit3d on every other frame: %s in %.1f s", ", ".join(
            f"{k} {v:.4g}" for k, v in terms.items()), time.perf_counter() - stage_start)
    for stage, iterations in stage_schedule(config, problem.cameras.moves, half_rate):
        if stage == "cameras" and shifts and shifts[-1] < config.round_stop_px:
            log.info("body fit: the cameras moved %.3f px in round %d (less than %g px): no further round",
                     shifts[-1], len(shifts), config.round_stop_px)
            break
        stage_start = time.perf_counter()
        before = problem.cameras.parameters().detach().clone() if stage == "cameras" else None
        # fit3d's every-frame steps continue the learning-rate decay where the half-rate steps left it
        schedule = (half_rate, config.iterations_3d) if stage == "fit3d" else None
        terms = run_stage(problem, stage, iterations, progress, schedule)
        if before is not None:
            shifts.append(_round_shift_px(problem, before))
        seconds[stage] += time.perf_counter() - stage_start
        log.info("body fit, %s: %s in %.1f s%s", stage, ", ".join(f"{k} {v:.4g}" for k, v in terms.items()),
                 time.perf_counter() - stage_start, f"; the cameras moved {shifts[-1]:.3f} px" if before is not None
                 else "")
    return _StagesRun(terms, seconds, tuple(shifts))


def _round_shift_px(problem: BodyFitProblem, before: Tensor) -> float:
    """How far the camera substage just run moved the cameras (``before``: their parameters at its start), over
    the people's keypoints of every present person-frame, pixels."""
    with torch.no_grad():
        keypoints, _, _ = problem.keypoints()
        return camera_shift_px(problem.cameras, before, keypoints[problem.present].reshape(-1, 3))


def _fit_half_rate(body: BodyModel, setup: _Setup, rig: CameraRig, config: BodyFitConfig, steps: int,
                   progress: Callable[[str, int, float], None] | None) -> dict[str, float]:
    """The first ``steps`` of fit3d on every other frame (the first part of its learning-rate decay); the problem
    on every frame then starts from that fit (:meth:`BodyFitProblem.take_half_rate`). Returns its last terms."""
    coarse = BodyFitProblem(body, setup.observations.every_other_frame(), rig, setup.prior, config, time_stride=2)
    coarse.encode_pose()
    terms = run_stage(coarse, "fit3d", steps, progress, schedule=(0, config.iterations_3d))
    setup.problem.take_half_rate(coarse)
    return terms


@dataclass(frozen=True)
class _FinalState:
    """The fitted people after the last stage (detached tensors).

    Attributes:
        keypoints: (P, T, 23, 3) keypoints, world metres.
        bone_rotmats: (P, T, 22, 3, 3) posed-bone rotations, root first.
        phenotypes: (P, 6) anny phenotypes in [0, 1].
        reprojection_px: mean pixel distance of the fitted keypoints to the detected ones
            (``BodyFitResult.reprojection_error_px``).
    """

    keypoints: Tensor
    bone_rotmats: Tensor
    phenotypes: Tensor
    reprojection_px: float


def _final_state(problem: BodyFitProblem) -> _FinalState:
    """The people's keypoints, bone rotations and phenotypes after the fit, and their reprojection error over every
    detected keypoint in front of its camera (NaN when there is none)."""
    with torch.no_grad():
        keypoints, _, rotmats = problem.keypoints()
        r2, weights = problem.reprojection(keypoints)
        detected = weights > 0
        reprojection_px = float(r2[detected].sqrt().mean()) if detected.any() else float("nan")
        phenotypes = problem.phenotypes()
    return _FinalState(keypoints, rotmats, phenotypes, reprojection_px)


def _to_numpy(values: Tensor) -> np.ndarray:
    """A tensor as a float64 array on the CPU."""
    return values.detach().cpu().double().numpy()


def _fitted_motions(final: _FinalState, problem: BodyFitProblem, observations: BodyObservations,
                    fps: float) -> FittedMotions:
    """The fitted people as :class:`FittedMotions` (float64 arrays)."""
    return FittedMotions(
        person_ids=observations.person_ids.astype(np.int64), frames=observations.frames.astype(np.int64),
        present=observations.present.copy(), phenotypes=_to_numpy(final.phenotypes),
        bone_rotmats_local=_to_numpy(final.bone_rotmats), root_translation_m=_to_numpy(problem.translation),
        keypoints_world_m=_to_numpy(final.keypoints), fps=float(fps))


MIN_STANDING_FRAMES = 5
"""Standing person-frames needed to re-level the floor after a camera refinement."""


def _relevel_floor(problem: BodyFitProblem) -> str | None:
    """After a fit with moving cameras, put the floor back at z = 0 (:func:`_level_floor`). Returns the warning
    when it could not be (too few standing person-frames), else None."""
    if problem.cameras.moves and _level_floor(problem) is None:
        return ("fewer than 5 standing person-frames: the floor was not re-levelled after the camera refinement "
                "(it stays where the calibration put it)")
    return None


def _level_floor(problem: BodyFitProblem) -> float | None:
    """Shift the world vertically so that the floor is at z = 0 again: the median lowest sole point over the
    standing person-frames (the calibration's rule, ``humancal.calibration.floor``). Returns the shift, metres
    (None: too few standing person-frames; nothing moved)."""
    with torch.no_grad():
        keypoints, _, _ = problem.keypoints()
        present = problem.present
        joints = keypoints[present].detach().cpu().double().numpy()  # (D, 23, 3)
        standing = standing_score(joints) >= 0.5
        if standing.sum() < MIN_STANDING_FRAMES:
            return None
        floor_z = float(np.median(joints[standing][:, list(FOOT_JOINTS), 2].min(axis=1)))
        offset = torch.tensor([0.0, 0.0, floor_z], dtype=problem.translation.dtype,
                              device=problem.translation.device)
        problem.translation -= offset
        problem.cameras.shift_world(offset)
        return floor_z
