"""Bundle adjustment of the cameras on the triangulated keypoints: the start of the joint refinement
(``BodyFitConfig.bundle_start``) and, followed by bodies with these cameras held, the paper's "separate" baseline.

The cameras are refined first, on their own, against free 3D points (the association's triangulated joints,
one point per person, frame and keypoint) and the same confidence-weighted Geman-McClure reprojection as the body
fit; the bodies are then fitted with these cameras held. Unlike the joint refinement, nothing ties the points to a
body (bone lengths, a plausible pose, smooth motion), which is what the comparison measures.

Points and cameras move together (one problem); the similarity that moves both at once is fixed by the weak tie
of each camera to its initial value (``BodyFitConfig.weight_camera_prior``). It runs in torch with the fit's own
camera parametrisation and robust cost, so the two regimes differ only in what the cameras are refined against.

Solvers (``BodyFitConfig.bundle_solver``):

* ``lm`` (default): the library's Levenberg-Marquardt (:mod:`humancal.least_squares`) on the Gauss-Newton system of the robust cost (iteratively reweighted:
  each residual weighted by the Geman-McClure derivative at the current state), with the points eliminated by
  the Schur complement: every point is seen once per view, so the point block is (N, 3, 3) block-diagonal and the
  reduced camera system is (V p) x (V p) for p parameters per view. The Jacobians come from p + 3 forward-mode
  passes (``torch.func.jvp``): a residual depends on one camera and one point, so a tangent that moves parameter
  k of every camera at once (or coordinate d of every point) gives that column for all residuals. A step is kept
  only if the robust cost falls; otherwise the damping grows and the step is tried again.
* ``lbfgs``: L-BFGS on the same cost (the earlier solver): on the ten sweep scenes it had not converged after
  its 100 iterations (``docs/refinement.md``, "The bundle adjustment's solver").
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from humancal.camera import CameraRig
from humancal.fitting.cameras import CameraVariables
from humancal.fitting.config import BodyFitConfig
from humancal.fitting.observations import BodyObservations, FittingInputError
from humancal.least_squares import ArrowSystem, Damping, Stop, levenberg_marquardt, solve_damped

__all__ = ["BundleResult", "bundle_adjust_on_joints"]


@dataclass(frozen=True)
class BundleResult:
    """A bundle adjustment's output.

    Attributes:
        cameras: the refined cameras.
        points_world_m: (P, T, 23, 3) the refined points (NaN where no triangulated joint was given, and in the
            frames left out: ``BodyFitConfig.bundle_max_frames``).
        reprojection_error_px: mean pixel distance of the refined points to their detections (confident ones).
        seconds: wall time.
        failure: why the adjustment was undone (its objective became non-finite: the cameras and points are then
            the initial ones), else None.
    """

    cameras: CameraRig
    points_world_m: np.ndarray
    reprojection_error_px: float
    seconds: float
    failure: str | None = None


def bundle_adjust_on_joints(observations: BodyObservations, rig: CameraRig, config: BodyFitConfig = BodyFitConfig(), *,
                  regime: str = "int_ext", iterations: int = 100, dtype: torch.dtype = torch.float64
                  ) -> BundleResult:
    """Refine the cameras (``regime``: ``ext`` or ``int_ext``) and the triangulated joints on the detections.

    Args:
        observations: the people's detections and triangulated joints (:func:`body_observations`).
        rig: the V initial cameras.
        config: the robust scales, the camera tie and the solver (``noise_px``, ``robust_scale_px``,
            ``weight_camera_prior``, ``camera_prior_scale_m``, ``refine_k1``, ``bundle_solver``).
        regime: which camera parameters move (``humancal.fitting.cameras``).
        iterations: at most this many Levenberg-Marquardt (or L-BFGS) iterations.

    Raises:
        FittingInputError: the views do not match the rig, or there is no confident detection of a valid joint.
    """
    if observations.num_views != len(rig):
        raise FittingInputError(f"bundle adjustment: detections of {observations.num_views} views, but {len(rig)} "
                                "cameras")
    start = time.perf_counter()
    cams = CameraVariables(rig, regime, refine_k1=config.refine_k1, dtype=dtype)
    if not cams.moves:
        raise ValueError("bundle adjustment: the cameras must move (regime 'ext' or 'int_ext'), got 'fixed'")
    stride = max(1, observations.num_frames // config.bundle_max_frames)
    used = observations.every_nth_frame(stride) if stride > 1 else observations
    valid = torch.as_tensor(used.joints_valid)
    points = torch.as_tensor(used.joints_world_m, dtype=dtype).clone()
    observed = torch.as_tensor(used.keypoints_px, dtype=dtype)[:, valid]  # (V, N, 2)
    weights = torch.as_tensor(used.confidence, dtype=dtype)[:, valid]  # (V, N)
    if not (weights > 0).any():
        raise FittingInputError("bundle adjustment: no confident detection of a triangulated joint")
    cost = _RobustReprojection(cams, observed, weights, config)
    free = points[valid].clone()
    variables = [*cams.variables(), free]
    snapshot = [v.detach().clone() for v in variables]
    failure = None
    try:
        if config.bundle_solver == "lm":
            _levenberg_marquardt(cost, free, iterations)
        else:
            _lbfgs(cost, free, iterations)
    except FloatingPointError as error:  # back to the start: never a rig of non-finite cameras
        failure = f"{error}; the initial cameras were kept"
        with torch.no_grad():
            for variable, saved in zip(variables, snapshot, strict=True):
                variable.copy_(saved)
    with torch.no_grad():
        residual, w = cost.residuals(cams.parameters(), free)
        error = float(residual.norm(dim=-1)[w > 0].mean())
        refined = torch.full_like(points, float("nan"))
        refined[valid] = free
    out = np.full(observations.joints_world_m.shape, np.nan)
    out[:, ::stride] = refined.numpy()
    return BundleResult(cams.to_rig(), out, error, time.perf_counter() - start, failure)


class _RobustReprojection:
    """The bundle adjustment's cost: the mean confidence-weighted Geman-McClure reprojection error (in units of
    the noise) plus the weak camera tie, as functions of the camera parameters (V, p) and the free points (N, 3)."""

    def __init__(self, cams: CameraVariables, observed: torch.Tensor, weights: torch.Tensor,
                 config: BodyFitConfig) -> None:
        self.cams, self.observed, self.weights = cams, observed, weights
        self.s2, self.n2 = config.robust_scale_px**2, config.noise_px**2
        self.tie_weight, self.tie_scale_m = config.weight_camera_prior, config.camera_prior_scale_m
        self.centre0 = cams.centre_m.detach().clone()

    def pixels(self, theta: torch.Tensor, free: torch.Tensor) -> torch.Tensor:
        """(V, N, 2) projections of the free points through the cameras at ``theta`` (V, p)."""
        return self.cams.tensors_at(**self.cams.unpack(theta)).project(free)[0]

    def residuals(self, theta: torch.Tensor, free: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Pixel residuals (V, N, 2) and their weights (V, N) (confidence, zero behind a camera)."""
        pixels, _, in_front = self.cams.tensors_at(**self.cams.unpack(theta)).project(free)
        return pixels - self.observed, self.weights * in_front.to(pixels.dtype)

    def tie(self, theta: torch.Tensor) -> torch.Tensor:
        values = self.cams.unpack(theta)
        return self.tie_weight * ((values["log_focal"] ** 2).mean() + (values["rotvec"] ** 2).mean()
                                  + (((values["centre_m"] - self.centre0) / self.tie_scale_m) ** 2).mean())

    def __call__(self, theta: torch.Tensor, free: torch.Tensor) -> torch.Tensor:
        residual, w = self.residuals(theta, free)
        r2 = (residual**2).sum(-1)
        data = (self.s2 * r2 / (r2 + self.s2) / self.n2 * w).sum() / w.sum()
        return data + self.tie(theta)


def _checked(value: torch.Tensor) -> torch.Tensor:
    if not torch.isfinite(value):
        raise FloatingPointError(f"bundle adjustment: the objective became {value.item()}")
    return value


def _lbfgs(cost: _RobustReprojection, free: torch.Tensor, iterations: int) -> None:
    cams = cost.cams
    free.requires_grad_()
    optimizer = torch.optim.LBFGS([*cams.variables(), free], lr=1.0, max_iter=iterations, history_size=10,
                                  line_search_fn="strong_wolfe", tolerance_grad=1e-9, tolerance_change=1e-12)

    def closure() -> torch.Tensor:
        optimizer.zero_grad(set_to_none=True)
        loss = _checked(cost(cams.parameters(), free))
        loss.backward()
        return loss

    optimizer.step(closure)
    free.requires_grad_(False)


_DAMPING = Damping(start=1e-3, grow=10.0, shrink=3.0, floor=1e-9, attempts=10)


def _levenberg_marquardt(cost: _RobustReprojection, free: torch.Tensor, iterations: int,
                         tolerance: float = 1e-4) -> None:
    """Minimise ``cost`` over the moving camera parameters and ``free`` (module docstring) with the library's
    Levenberg-Marquardt (:mod:`humancal.least_squares`); writes the result into the camera variables and ``free``
    in place."""
    cams = cost.cams

    def linearize(state):
        theta, X = state
        return _normal_equations(cost, theta, X), cost(theta, X)

    def trial(state, system, damping):
        theta, X = state
        step = solve_damped(system, damping)
        if not bool(step.solved.all()):  # a singular system: refused, the damping grows
            return state, float("inf")
        new_theta, new_X = theta + step.global_step.reshape(theta.shape), X + step.block_step
        return (new_theta, new_X), cost(new_theta, new_X)

    with torch.no_grad():
        start = (cams.parameters().detach().clone(), free.detach().clone())
        _checked(cost(*start))
        outcome = levenberg_marquardt(linearize, trial, start, max_iterations=iterations, damping=_DAMPING,
                                      stop=Stop(tolerance), relinearize_last=False)
        theta, X = outcome.state
        cams.assign(theta)
        free.copy_(X)


def _normal_equations(cost: _RobustReprojection, theta: torch.Tensor, X: torch.Tensor):
    """The Gauss-Newton system of the robust cost at (theta, X), reweighted by the Geman-McClure derivative: the
    cameras' V p parameters global, one block per point (3)."""
    V, p = theta.shape
    residual, w = cost.residuals(theta, X)  # (V, N, 2), (V, N)
    r2 = (residual**2).sum(-1)
    # d/d(r2) of s2 r2 / (r2 + s2) = (s2 / (r2 + s2))^2; the factor 2 of d(r2)/dr and the mean's normaliser
    a = 2.0 * w * (cost.s2 / (r2 + cost.s2)) ** 2 / cost.n2 / w.sum()  # (V, N)

    def column(t_theta: torch.Tensor, t_X: torch.Tensor) -> torch.Tensor:
        return torch.func.jvp(cost.pixels, (theta, X), (t_theta, t_X))[1]

    J_c = torch.stack([column(_unit_column(theta, k), torch.zeros_like(X)) for k in range(p)], dim=-1)
    J_p = torch.stack([column(torch.zeros_like(theta), _unit_column(X, d)) for d in range(3)], dim=-1)
    aJ_c = a[..., None, None] * J_c  # (V, N, 2, p)
    H_blocks = torch.einsum("vnip,vniq->vpq", aJ_c, J_c)
    H_cp = torch.einsum("vnip,vnia->vnpa", aJ_c, J_p)
    H_pp = torch.einsum("vn,vnia,vnib->nab", a, J_p, J_p)
    g_c = torch.einsum("vnip,vni->vp", aJ_c, residual)
    g_p = torch.einsum("vn,vnia,vni->na", a, J_p, residual)
    # the camera tie: exact gradient and Hessian (a quadratic in the parameters)
    flat = theta.detach().clone().requires_grad_()
    with torch.enable_grad():
        tie_grad = torch.autograd.grad(cost.tie(flat), flat)[0]
        tie_hess = torch.autograd.functional.hessian(lambda t: cost.tie(t.reshape(V, p)), theta.reshape(-1))
    H_cc = torch.zeros(V, p, V, p, dtype=theta.dtype)
    H_cc[torch.arange(V), :, torch.arange(V), :] = H_blocks
    H_cc = H_cc + tie_hess.reshape(V, p, V, p)
    N = X.shape[0]
    return ArrowSystem(H_cc.reshape(V * p, V * p), H_pp, H_cp.permute(1, 3, 0, 2).reshape(N, 3, V * p),
                       (g_c + tie_grad).reshape(V * p), g_p)


def _unit_column(like: torch.Tensor, k: int) -> torch.Tensor:
    out = torch.zeros_like(like)
    out[:, k] = 1.0
    return out
