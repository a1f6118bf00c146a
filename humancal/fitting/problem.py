"""The variables and the objective of a body fit, and the optimisation of one of its stages
(:func:`humancal.fitting.fit_bodies` runs them in turn; the method is in ``humancal.fitting.fit``'s docstring).

Variables per person: the body shape (anny phenotypes through a logistic map, starting at ``INITIAL_PHENOTYPES``),
the root orientation (6D) and translation of every frame, and the body pose of every frame (the 21 bones' 6D
rotations, or the motion prior's latent windows once :meth:`BodyFitProblem.encode_pose` swaps them in); per camera,
what ``BodyFitConfig.cameras`` lets move (``humancal.fitting.cameras``). The terms (:meth:`BodyFitProblem.terms`) are
unweighted; :meth:`BodyFitProblem.total` weighs them as ``BodyFitConfig`` says. :func:`run_stage` optimises one
stage's variables: Adam on the triangulated joints (``fit3d``), L-BFGS on the detections (the others).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import torch
from torch import Tensor

from humancal.body import BodyModel, RestSkeleton
from humancal.camera import CameraRig
from humancal.fitting.cameras import CameraVariables
from humancal.fitting.config import BodyFitConfig
from humancal.fitting.contact import interpenetration
from humancal.fitting.observations import BodyObservations
from humancal.fitting.schedule import upsample_frames
from humancal.prior.config import NUM_PRIOR_BONES
from humancal.prior.latent_fit import KeypointObservations, initial_root
from humancal.prior.model import MotionVAE, identity_pose6d, pose6d_to_rotmats, rotmats_to_pose6d, with_root
from humancal.prior.windows import window_layout

__all__ = ["BodyFitProblem", "INITIAL_PHENOTYPES", "run_stage"]

log = logging.getLogger(__name__)

INITIAL_PHENOTYPES = (0.5, 2.0 / 3.0, 0.5, 0.5, 0.5, 0.5)
"""Where every body starts: an average young adult (anny's gender 0.5, age 2/3 = 25 years, the rest at 0.5)."""


def _geman_mcclure(r2: Tensor, scale: float, noise: float) -> Tensor:
    """Robust cost of squared residuals ``r2`` (module docstring of ``humancal.fitting.config``)."""
    s2 = scale * scale
    return s2 * r2 / (r2 + s2) / (noise * noise)


def _weighted_mean(values: Tensor, weights: Tensor) -> Tensor:
    """Mean of ``values`` weighted by ``weights`` (same shape); 0 when every weight is 0."""
    return (values * weights).sum() / weights.sum().clamp(min=1e-12)


def _mean_square(x: Tensor) -> Tensor:
    """Mean of the squared entries; 0 for an empty tensor."""
    return (x**2).mean() if x.numel() else x.new_zeros(())


def _second_difference(x: Tensor, dim: int) -> Tensor:
    """``x[t + 1] - 2 x[t] + x[t - 1]`` along ``dim`` (two entries shorter there; empty when it has fewer than 3)."""
    n = x.shape[dim]
    if n < 3:
        return x.new_zeros(0)
    return x.narrow(dim, 2, n - 2) - 2.0 * x.narrow(dim, 1, n - 2) + x.narrow(dim, 0, n - 2)


class BodyFitProblem:
    """The variables and terms of one body fit (:func:`humancal.fitting.fit_bodies` drives it; its stages choose
    the variables they move, :meth:`stage_variables`, and the data they fit, :meth:`terms`)."""

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

    def take_half_rate(self, coarse: BodyFitProblem) -> None:
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


def run_stage(problem: BodyFitProblem, stage: str, iterations: int,
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


def _optimize(problem: BodyFitProblem, stage: str, data: str, variables: list[Tensor], iterations: int,
              progress: Callable[[str, int, float], None] | None,
              schedule_window: tuple[int, int] | None = None) -> dict[str, float]:
    """Optimise ``variables`` on the ``data`` terms (:func:`run_stage`); a non-finite objective restores them to
    the stage's start. Returns the last terms, unweighted, and ``total`` (weighted)."""
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
