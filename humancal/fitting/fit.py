"""Bodies and motions of every person fitted to the associated detections, cameras held fixed (the paper's III-E).

Variables per person: the body shape (anny phenotypes, through a logistic map so they stay in [0, 1]), the
root orientation (6D) and translation of every frame, and the body pose of every frame: the motion prior's
latent codes (T x 32, decoder frozen) or, for the no-prior baseline, the 21 bones' 6D rotations.

Variables per camera (``BodyFitConfig.cameras``, ``humancal.fitting.cameras``): none (``fixed``), the extrinsics
(``ext``), or the focal length and the extrinsics (``int_ext``: fully self-calibrated).

Objective (``BodyFitConfig`` documents the units): a confidence-weighted Geman-McClure reprojection term of the
23 canonical keypoints in every view, through the shared camera model (``humancal.geometry.projection``); the
latent prior ``mean(z^2)``; the local-linear term ``mean((z[t+1] - 2 z[t] + z[t-1])^2)``; a shape prior; a root
smoothness term; for long sequences cut into windows (``humancal.prior.windows``), a seam term; the
interpenetration of different people (``humancal.fitting.contact``); and, when the cameras move, a weak tie of
each camera to its initial value.

Schedule: when the cameras move, they first take a bundle adjustment on the triangulated joints as free points
(``BodyFitConfig.bundle_start``, :func:`humancal.fitting.bundle.bundle_adjust`: the ``separate`` baseline's
cameras), and the joint refinement starts from there (chosen on synthetic scenes whose detector has its own
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

from humancal.body import BodyModel, RestSkeleton
from humancal.camera import CameraRig
from humancal.calibration.types import FOOT_JOINTS
from humancal.fitting.bundle import bundle_adjust
from humancal.fitting.cameras import CameraVariables
from humancal.fitting.config import BodyFitConfig
from humancal.fitting.contact import interpenetration
from humancal.fitting.motions import FittedMotions
from humancal.fitting.observations import BodyObservations, FittingInputError, unswap_left_right
from humancal.fitting.schedule import half_rate_steps, stage_schedule, upsample_frames
from humancal.lifter.pose_cues import standing_score
from humancal.prior.config import NUM_PRIOR_BONES
from humancal.prior.fitting import KeypointObservations, initial_root
from humancal.prior.model import MotionVAE, identity_pose6d, pose6d_to_rotmats, rotmats_to_pose6d, with_root
from humancal.prior.windows import window_layout

__all__ = ["BodyFitResult", "fit_bodies", "INITIAL_PHENOTYPES", "STAGES"]

log = logging.getLogger(__name__)

INITIAL_PHENOTYPES = (0.5, 2.0 / 3.0, 0.5, 0.5, 0.5, 0.5)
"""Where every body starts: an average young adult (anny's gender 0.5, age 2/3 = 25 years, the rest at 0.5)."""

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
    """

    motions: FittedMotions
    cameras: CameraRig
    latents: np.ndarray | None
    stage_seconds: dict[str, float]
    loss_terms: dict[str, float]
    reprojection_error_px: float
    warnings: tuple[str, ...] = ()


def _geman_mcclure(r2: Tensor, scale: float, noise: float) -> Tensor:
    """Robust cost of squared residuals ``r2`` (module docstring of ``humancal.fitting.config``)."""
    s2 = scale * scale
    return s2 * r2 / (r2 + s2) / (noise * noise)


def _weighted_mean(values: Tensor, weights: Tensor) -> Tensor:
    return (values * weights).sum() / weights.sum().clamp(min=1e-12)


def _mean_square(x: Tensor) -> Tensor:
    return (x**2).mean() if x.numel() else x.new_zeros(())


def _second_difference(x: Tensor, dim: int) -> Tensor:
    n = x.shape[dim]
    if n < 3:
        return x.new_zeros(0)
    return x.narrow(dim, 2, n - 2) - 2.0 * x.narrow(dim, 1, n - 2) + x.narrow(dim, 0, n - 2)


class _Problem:
    """The variables and terms of one fit (internal: :func:`fit_bodies` drives it)."""

    def __init__(self, body: BodyModel, observations: BodyObservations, rig: CameraRig, prior: MotionVAE | None,
                 config: BodyFitConfig, time_stride: int = 1) -> None:
        self.body, self.config, self.prior = body, config, prior
        # frames apart of consecutive frames here (2: the half-rate start): the temporal terms' scales follow it
        self.time_stride = time_stride
        to = self.to = dict(dtype=body.dtype, device=body.device)
        P, T = observations.num_people, observations.num_frames
        self.P, self.T = P, T
        self.cameras = CameraVariables(rig, config.cameras, refine_k1=config.refine_k1, **to)
        self.fixed_rig = rig.to_torch(**to) if not self.cameras.moves else None
        self.present = torch.as_tensor(observations.present, device=body.device)
        self.centre0_m = self.cameras.centre_m.detach().clone()
        self.held_people: tuple[Tensor, Tensor | None, Tensor] | None = None
        self.held_pose: tuple[Tensor, Tensor | None, RestSkeleton] | None = None
        self.keypoints_px = torch.as_tensor(observations.keypoints_px, **to)
        self.confidence = torch.as_tensor(observations.confidence, **to)
        self.joints = torch.as_tensor(observations.joints_world_m, **to)
        self.joints_weight = torch.as_tensor(observations.joints_valid, **to)
        self.layout = window_layout(T, config.window_frames, config.window_overlap)
        self.phenotypes0 = torch.tensor(INITIAL_PHENOTYPES, **to).expand(P, -1).clone()
        self.shape_logit = torch.logit(self.phenotypes0).clone().requires_grad_(config.fit_shape)

        with torch.no_grad():
            rest = body.rest_skeleton(self.phenotypes0)
            points = KeypointObservations(self.joints, torch.as_tensor(observations.joints_valid, device=body.device),
                                          noise_scale=config.noise_3d_m)
            root_R, root_t = initial_root(body, rest, points)
        self.root6d = rotmats_to_pose6d(root_R).clone().requires_grad_()
        self.translation = root_t.clone().requires_grad_()
        identity = identity_pose6d(**to)
        # The body pose starts as the reference pose in raw 6D rotations; a prior fit swaps them for their
        # latent codes (:meth:`encode_pose`).
        self.pose_params = identity.expand(P, T, NUM_PRIOR_BONES, 6).clone().requires_grad_()
        self.latent = False
        self.identity6d = identity

    # ---------------------------------------------------------------------------------------------- model

    def encode_pose(self) -> None:
        """Swap the raw 6D body pose for latent windows: the prior's mean (``latent_start="prior_mean"``) or the
        prior's encoding of the raw pose, one window at a time (``"reference_pose"``: the pose is still the
        reference pose when this runs)."""
        if self.prior is None or self.latent:
            return
        with torch.no_grad():
            # the encoder reads exact 6D forms: normalise the raw ones first (Gram-Schmidt and back)
            pose6d = rotmats_to_pose6d(pose6d_to_rotmats(self.pose_params.detach()))
            windows = self.layout.split(pose6d)  # (P, W, L, 21, 6)
            P, W, L = windows.shape[:3]
            if self.config.latent_start == "prior_mean":
                mu = windows.new_zeros(P, W, L, self.prior.config.latent_dim)
            else:
                mu, _ = self.prior.encode(windows.reshape(P * W, L, NUM_PRIOR_BONES, 6))
        self.pose_params = mu.reshape(P, W, L, -1).clone().requires_grad_()
        self.latent = True

    def take_half_rate(self, coarse: _Problem) -> None:
        """Start from a fit of every other frame (``coarse``, ``time_stride`` 2): its shape, and its roots and body
        pose interpolated linearly in time to every frame (the latent codes too: the local-linear term keeps them
        nearly linear between neighbouring frames). A person with no triangulated joint on those frames (a short
        track seen on odd frames only) keeps this problem's own start."""
        seen = coarse.joints_weight.flatten(1).sum(1) > 0  # (P,)

        def take(variable: Tensor, value: Tensor) -> None:
            variable.copy_(torch.where(seen.reshape(-1, *[1] * (variable.dim() - 1)), value, variable))

        with torch.no_grad():
            take(self.shape_logit, coarse.shape_logit)
            take(self.root6d, upsample_frames(coarse.root6d, self.T))
            take(self.translation, upsample_frames(coarse.translation, self.T))
            if self.latent:
                per_frame = upsample_frames(coarse.layout.assemble(coarse.pose_params), self.T)
                take(self.pose_params, self.layout.split(per_frame))
            else:
                take(self.pose_params, upsample_frames(coarse.pose_params, self.T))

    def phenotypes(self) -> Tensor:
        return torch.sigmoid(self.shape_logit)

    def pose6d(self) -> tuple[Tensor, Tensor | None]:
        """(P, T, 21, 6) body pose of every frame, and the (P, S, 21, 6) seam differences (None: no windows)."""
        if not self.latent:
            return self.pose_params, None
        P, W, L, D = self.pose_params.shape
        decoded = self.prior.decode(self.pose_params.reshape(P * W, L, D)).reshape(P, W, L, NUM_PRIOR_BONES, 6)
        return self.layout.assemble(decoded), self.layout.seam_difference(decoded)

    def bone_rotmats(self, pose6d: Tensor) -> Tensor:
        return with_root(pose6d_to_rotmats(pose6d), pose6d_to_rotmats(self.root6d))

    def keypoints(self) -> tuple[Tensor, Tensor | None, Tensor]:
        """(P, T, 23, 3) keypoints, the seam differences and the (P, T, 22, 3, 3) bone rotations (the held
        people's, computed once, while only the cameras move; the held body pose and shape, decoded once, while
        only the roots move)."""
        if self.held_people is not None:
            return self.held_people
        if self.held_pose is not None:
            pose6d, seam, rest = self.held_pose
        else:
            pose6d, seam = self.pose6d()
            rest = self.body.rest_skeleton(self.phenotypes())
        rotmats = self.bone_rotmats(pose6d)
        return self.body.keypoints(rest, rotmats, self.translation), seam, rotmats

    def reprojection(self, keypoints: Tensor) -> tuple[Tensor, Tensor]:
        """(V, P, T, 23) squared pixel residuals and the weights (confidence, 0 behind a camera)."""
        rig = self.fixed_rig if self.fixed_rig is not None else self.cameras.tensors()
        pixels, _, in_front = rig.project(keypoints.reshape(-1, 3))
        pixels = pixels.reshape(-1, self.P, self.T, keypoints.shape[2], 2)
        r2 = ((pixels - self.keypoints_px) ** 2).sum(-1)
        weights = self.confidence * in_front.reshape(r2.shape).to(self.confidence.dtype)
        return r2, weights

    # ---------------------------------------------------------------------------------------------- terms

    def terms(self, data: str) -> dict[str, Tensor]:
        """Every (unweighted) term; ``data`` is ``"3d"`` (triangulated joints) or ``"2d"`` (detections)."""
        c = self.config
        keypoints, seam, _ = self.keypoints()
        out: dict[str, Tensor] = {}
        if data == "3d":
            r2 = ((keypoints - self.joints) ** 2).sum(-1)
            out["data_3d"] = _weighted_mean(_geman_mcclure(r2, c.robust_scale_3d_m, c.noise_3d_m), self.joints_weight)
        else:
            r2, weights = self.reprojection(keypoints)
            out["reprojection"] = _weighted_mean(_geman_mcclure(r2, c.robust_scale_px, c.noise_px), weights)
        scale = c.root_smooth_scale_m * self.time_stride**2  # a second difference grows as the frame step squared
        out["root_smooth"] = _mean_square(_second_difference(self.translation, 1) / scale) + \
            _mean_square(_second_difference(self.root6d, 1) / scale)
        out["shape"] = _mean_square(self.phenotypes() - self.phenotypes0)
        if self.latent:
            out["latent"] = _mean_square(self.pose_params)
            out["local_linear"] = _mean_square(_second_difference(self.pose_params, 2))
            out["seam"] = _mean_square(seam) if seam is not None else keypoints.new_zeros(())
        else:
            out["rest"] = _mean_square(self.pose_params - self.identity6d)
        if c.weight_interpenetration > 0 and self.P > 1 and data == "2d":
            # not in the first stage: its people start in the reference pose, arms out, overlapping their
            # neighbours; pushed apart there, they end beyond the data term's robust range
            out["interpenetration"] = interpenetration(keypoints, self.present) / c.contact_scale_m**2
        if self.cameras.moves and data == "2d":
            cams = self.cameras
            out["camera_prior"] = _mean_square(cams.log_focal) + _mean_square(cams.rotvec) + \
                _mean_square((cams.centre_m - self.centre0_m) / c.camera_prior_scale_m)
        return out

    def total(self, terms: dict[str, Tensor]) -> Tensor:
        c = self.config
        local_linear = c.weight_local_linear_3d if "data_3d" in terms else c.weight_local_linear
        local_linear /= self.time_stride**4  # the same smoothness per unit of time at a coarser frame step
        if self.prior is not None and not self.prior.config.temporal:
            local_linear = 0.0  # a per-frame prior is the baseline without dynamics: no smoothness of its latents
        weights = {"data_3d": 1.0, "reprojection": 1.0, "root_smooth": c.weight_root_smooth, "shape": c.weight_shape,
                   "latent": c.weight_latent, "local_linear": local_linear, "seam": c.weight_seam,
                   "rest": c.weight_rest, "interpenetration": c.weight_interpenetration,
                   "camera_prior": c.weight_camera_prior}
        return sum(weights[name] * value for name, value in terms.items())

    def stage_variables(self, stage: str) -> list[Tensor]:
        shape = [self.shape_logit] if self.config.fit_shape else []
        if stage == "global":
            return [self.root6d, self.translation]
        if stage == "cameras":
            return self.cameras.variables()
        return [*shape, self.root6d, self.translation, self.pose_params]


def _run_stage(problem: _Problem, stage: str, iterations: int,
               progress: Callable[[str, int, float], None] | None,
               schedule: tuple[int, int] | None = None) -> dict[str, float]:
    """Adam (``fit3d``) or L-BFGS with a strong-Wolfe line search (the 2D stages) on one stage's variables; the
    last terms, unweighted (and ``total``, weighted). ``schedule``: ``(first step, all steps)`` of Adam's linear
    learning-rate decay when this run is a part of it (default: the whole of it)."""
    data = "3d" if stage == "fit3d" else "2d"
    variables = problem.stage_variables(stage)
    if stage == "cameras":  # the people are held: their keypoints once, not at every evaluation
        with torch.no_grad():
            problem.held_people = problem.keypoints()
        try:
            return _optimize(problem, stage, data, variables, iterations, progress)
        finally:
            problem.held_people = None
    if stage == "global":  # body pose and shape held: decoded once, and no gradient through the decoder
        with torch.no_grad():
            pose6d, seam = problem.pose6d()  # the no-prior fit's pose is its own leaf: detached here
            problem.held_pose = (pose6d.detach(), seam, problem.body.rest_skeleton(problem.phenotypes()))
        try:
            return _optimize(problem, stage, data, variables, iterations, progress)
        finally:
            problem.held_pose = None
    return _optimize(problem, stage, data, variables, iterations, progress, schedule)


def _optimize(problem: _Problem, stage: str, data: str, variables: list[Tensor], iterations: int,
              progress: Callable[[str, int, float], None] | None,
              schedule_window: tuple[int, int] | None = None) -> dict[str, float]:
    if iterations == 0:
        with torch.no_grad():
            return {k: float(v) for k, v in problem.terms(data).items()}
    if stage != "fit3d":  # refinement from a good start: quasi-Newton
        optimizer = torch.optim.LBFGS(variables, lr=1.0, max_iter=iterations, history_size=10,
                                      line_search_fn="strong_wolfe", tolerance_grad=1e-9, tolerance_change=1e-12)
        steps, schedule = 1, None
    else:  # thousands of nearly separable per-frame problems far from their solution: Adam's per-variable steps
        optimizer = torch.optim.Adam(variables, lr=problem.config.learning_rate_3d)
        steps = iterations
        first, total = schedule_window or (0, iterations)
        schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda i: 1.0 - 0.9 * (first + i) / total)
    calls = [0]

    def closure() -> Tensor:
        optimizer.zero_grad(set_to_none=True)
        loss = problem.total(problem.terms(data))
        if not torch.isfinite(loss):
            raise FloatingPointError(f"body fit, stage {stage}: the objective became {float(loss)}")
        loss.backward()
        calls[0] += 1
        if progress is not None:
            progress(stage, calls[0], float(loss.detach()))
        return loss

    snapshot = [v.detach().clone() for v in variables]
    try:
        for _ in range(steps):
            optimizer.step(closure)
            if schedule is not None:
                schedule.step()
    except FloatingPointError as error:  # a line search that left the valid region: back to the stage's start
        log.warning("%s; the stage's variables are restored", error)
        with torch.no_grad():
            for v, s in zip(variables, snapshot):
                v.copy_(s)
    with torch.no_grad():
        terms = problem.terms(data)
        terms["total"] = problem.total(terms)
        return {k: float(v) for k, v in terms.items()}


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
    seconds: dict[str, float] = {}
    start = time.perf_counter()
    seconds["bundle"] = 0.0
    fit_warnings = list(warnings)
    if config.bundle_start and config.cameras != "fixed":
        bundle = bundle_adjust(observations, rig, config, regime=config.cameras)
        rig = bundle.cameras
        seconds["bundle"] = time.perf_counter() - start
        if bundle.failure:
            fit_warnings.append(bundle.failure)
            log.warning("body fit: %s", bundle.failure)
        else:
            log.info("body fit: cameras bundle-adjusted on the triangulated joints in %.1f s", seconds["bundle"])
    prepare_start = time.perf_counter()
    if config.unswap_left_right:
        observations, swapped = unswap_left_right(observations, rig, min_error_px=config.noise_px)
        log.info("body fit: %d detection(s) with left and right swapped back", swapped)
    if prior is not None:
        prior = prior.to(dtype=body.dtype, device=body.device).eval()
    problem = _Problem(body, observations, rig, prior, config)
    problem.encode_pose()  # prior fits: from here the body pose is the latent motion
    seconds["prepare"] = time.perf_counter() - prepare_start
    terms: dict[str, float] = {}
    for stage in STAGES:
        seconds[stage] = 0.0
    half_rate = half_rate_steps(config, observations.num_frames)
    if half_rate:
        stage_start = time.perf_counter()
        coarse = _Problem(body, observations.every_other_frame(), rig, prior, config, time_stride=2)
        coarse.encode_pose()
        terms = _run_stage(coarse, "fit3d", half_rate, progress, schedule=(0, config.iterations_3d))
        problem.take_half_rate(coarse)
        seconds["fit3d"] += time.perf_counter() - stage_start
        log.info("body fit, fit3d on every other frame: %s in %.1f s", ", ".join(
            f"{k} {v:.4g}" for k, v in terms.items()), time.perf_counter() - stage_start)
    for stage, iterations in stage_schedule(config, problem.cameras.moves, half_rate):
        stage_start = time.perf_counter()
        # fit3d's every-frame steps continue the learning-rate decay where the half-rate steps left it
        schedule = (half_rate, config.iterations_3d) if stage == "fit3d" else None
        terms = _run_stage(problem, stage, iterations, progress, schedule)
        seconds[stage] += time.perf_counter() - stage_start
        log.info("body fit, %s: %s in %.1f s", stage, ", ".join(f"{k} {v:.4g}" for k, v in terms.items()),
                 time.perf_counter() - stage_start)
    stage_start = time.perf_counter()
    if problem.cameras.moves:
        floor = _level_floor(problem)
        if floor is None:
            fit_warnings.append("fewer than 5 standing person-frames: the floor was not re-levelled after the "
                                "camera refinement (it stays where the calibration put it)")
    seconds["floor"] = time.perf_counter() - stage_start
    with torch.no_grad():
        keypoints, _, rotmats = problem.keypoints()
        r2, weights = problem.reprojection(keypoints)
        detected = weights > 0
        reprojection_px = float(r2[detected].sqrt().mean()) if detected.any() else float("nan")
        phenotypes = problem.phenotypes()
    seconds["total"] = time.perf_counter() - start
    as_np = lambda t: t.detach().cpu().double().numpy()  # noqa: E731
    motions = FittedMotions(
        person_ids=observations.person_ids.astype(np.int64), frames=observations.frames.astype(np.int64),
        present=observations.present.copy(), phenotypes=as_np(phenotypes), bone_rotmats_local=as_np(rotmats),
        root_translation_m=as_np(problem.translation), keypoints_world_m=as_np(keypoints), fps=float(fps))
    latents = as_np(problem.pose_params) if problem.latent else None
    cameras = problem.cameras.to_rig() if problem.cameras.moves else rig
    return BodyFitResult(motions, cameras, latents, seconds, terms, reprojection_px,
                         tuple(fit_warnings))


MIN_STANDING_FRAMES = 5
"""Standing person-frames needed to re-level the floor after a camera refinement."""


def _level_floor(problem: _Problem) -> float | None:
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
