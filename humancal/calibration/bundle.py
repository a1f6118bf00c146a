"""Multi-view refinement of focal lengths and extrinsics: a bundle adjustment over matched people.

Unknowns: per view the focal length(s) (log), a rotation increment and the translation (camera 0 keeps its
rotation and translation: it is the world frame until the floor alignment); per group (one person in one
frame, matched across views) the 3D positions of the 23 canonical keypoints.

Residuals (all in units of their standard deviation):

* reprojection of every detected keypoint, std ``max(1 %`` of the person's image size, 1 px) / sqrt(score);
* agreement of each group's keypoints, relative to their hip midpoint and turned into each view's camera
  frame, with that view's lifted pose (std ``shape_std_m``): this gives the metric scale (from body size)
  and holds joints seen in one view only;
* optional priors on the log focal lengths (from the single-view estimates, weighted by their uncertainty);
* with a lens model (``lens="k1"`` or ``"k1k2"``, ``principal_point=True``): zero-mean priors on each view's radial
  coefficients and on its principal point's offset from the one given (``lens_prior_std``).

Reprojection and shape residuals are robustified with Huber weights (iteratively reweighted). The solver is
the library's Levenberg-Marquardt (:mod:`humancal.least_squares`) on the normal equations, with the Schur
complement over the per-group point blocks (the residuals and normal equations live in :mod:`.bundle_terms`), so
the cost grows linearly with the number of groups (scipy's ``least_squares`` solves the reduced camera system with an iterative sparse solver that does not
exploit the 70 x 70 point blocks: the direct Schur solve is kept).

The solver cannot diverge:

* each focal length is bounded by its parameterization, ``log f = m + h tanh(u)``, to a plausible horizontal
  field of view (10-140 degrees by default, ``focal_bounds_px`` otherwise): a focal never runs off to 1e12 px
  when a view's observations pull it towards an affine camera, it stops at the bound (``"focal_at_bound"``);
* a step is only taken when it lowers the cost and every parameter and the cost are finite (a singular or
  non-finite system, or a cost increase, raises the damping and retries from the last good state; after ten
  refusals the last good state is the result);
* the inputs are checked first (non-finite starting cameras raise :class:`CalibrationError` naming the view;
  joints of non-finite lifted poses or keypoints are left out of their residuals);
* every view ends with a status (:attr:`BundleResult.view_status`). Unlike the linear solve of :mod:`.translations`, the noisy
measurements (2D keypoints, lifted poses) are residuals here, not regressors, so the focal lengths are not
biased by errors in variables.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from humancal.calibration.bundle_setup import (
    BundleSetup,
    bundle_setup,
    check_start,
    free_parameters,
    start_cameras,
)
from humancal.calibration.bundle_terms import (
    _focal_count,
    _lens,
    _log_focal,
    _normal_equations,
    _Problem,
    _residuals,
    _robust_cost,
    _solve,
    _unpack,
)
from humancal.calibration.bundle_uncertainty import camera_std
from humancal.calibration.types import CalibrationError
from humancal.geometry.rotations import rotvec_to_rotmat
from humancal.least_squares import Damping, Stop, levenberg_marquardt
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = ["BundleResult", "bundle_adjust", "focal_bounds_from_fov"]

_STILL_ITERATIONS = 3
"""Iterations in a row with the cameras still (``camera_tolerance``) after which the bundle adjustment stops: the
points and sizes can crawl on for tens of iterations at a relative cost decrease of 1e-5 while the cameras move by
less than 1e-5; along a flat valley the cameras still move, and it does not fire."""

_DAMPING = Damping(start=1e-3, grow=10.0, shrink=5.0, floor=1e-7, attempts=10)
"""The Levenberg-Marquardt schedule: ten refusals in a row (damping 1e-3 -> 1e7 times the diagonal) end it."""

logger = logging.getLogger(__name__)



@dataclass(frozen=True)
class BundleResult:
    """Result of :func:`bundle_adjust`.

    Attributes:
        fx_px, fy_px: (V,) focal lengths, pixels.
        R_cam_from_world: (V, 3, 3) rotations.
        t_cam_from_world_m: (V, 3) translations, metres.
        points_world_m: (G, 23, 3) keypoints of the groups, metres.
        focal_rel_std: (V,) relative standard deviation of the focal lengths (inverse Schur complement); inf for
            a focal at a bound of its range (undetermined), NaN for a held view.
        reprojection_rms_px: (V,) RMS reprojection error of the inlier keypoints per view, pixels.
        inlier_fraction: fraction of keypoint observations within the Huber threshold.
        iterations: LM iterations run.
        converged: whether the relative cost decrease fell under the tolerance.
        group_scale: (G,) size of each group's lifted poses relative to its keypoints (``q``; ones when the
            scales were not estimated).
        view_status: (V,) per view ``"ok"``, ``"focal_at_bound"`` (the focal ended within 2 % of a bound of
            its plausible range), ``"behind_camera"`` (most of its keypoints behind it), ``"no_inliers"`` (no
            keypoint within the Huber threshold) or ``"held"`` (in ``hold_views``).
        rejected_steps: steps refused (cost increase, non-finite values or a singular system).
        cost: the final robust cost (comparable between runs on the same groups and priors).
        distortion: (V, 5) OpenCV ``(k1, k2, p1, p2, k3)`` of every view (zeros without a lens model).
        principal_point_px: (V, 2) principal points (the ones given unless ``principal_point`` let them move).
        lens_std: (V, 4) std of ``k1, k2, dcx_px, dcy_px`` as the focal's (:func:`.bundle_uncertainty.camera_std`); NaN where held.
        detection_error_sigma: (S,) per detection of the groups (the rows of ``np.concatenate(groups)``, in that
            order) the median reprojection error of its keypoints in units of their std (1 % of the person's
            image extent, at least 1 px; see the module docstring), NaN where none of its keypoints was used:
            about 1 for a detection of the right person, tens for one matched to the wrong person.
    """

    fx_px: np.ndarray
    fy_px: np.ndarray
    R_cam_from_world: np.ndarray
    t_cam_from_world_m: np.ndarray
    points_world_m: np.ndarray
    focal_rel_std: np.ndarray
    reprojection_rms_px: np.ndarray
    inlier_fraction: float
    iterations: int
    converged: bool
    group_scale: np.ndarray | None = None
    view_status: np.ndarray | None = None
    rejected_steps: int = 0
    cost: float = float("nan")
    detection_error_sigma: np.ndarray | None = None
    distortion: np.ndarray | None = None
    principal_point_px: np.ndarray | None = None
    lens_std: np.ndarray | None = None


def focal_bounds_from_fov(width_px: np.ndarray, fov_range_deg: tuple[float, float] = (10.0, 140.0)) -> np.ndarray:
    """(V, 2) focal bounds (low, high) in pixels giving a horizontal field of view in ``fov_range_deg``.

    Args:
        width_px: (V,) image widths, pixels.
        fov_range_deg: (narrowest, widest) horizontal field of view, degrees, in (0, 180).

    Raises:
        ValueError: the range is not ``0 < narrow < wide < 180`` or a width is not positive.
    """
    lo_deg, hi_deg = fov_range_deg
    if not 0.0 < lo_deg < hi_deg < 180.0:
        raise ValueError(f"fov_range_deg={fov_range_deg} must be 0 < narrowest < widest < 180 degrees")
    w = np.asarray(width_px, dtype=np.float64)
    if not (np.isfinite(w).all() and (w > 0).all()):
        raise ValueError(f"width_px must be positive and finite, got {w}")
    half = 0.5 * w
    return np.stack([half / np.tan(np.radians(hi_deg) / 2), half / np.tan(np.radians(lo_deg) / 2)], -1)


def bundle_adjust(
    detections: DenseDetections, lifted: LiftedPoses, groups: list[np.ndarray], points_world_m: np.ndarray,
    fx_px: np.ndarray, fy_px: np.ndarray, principal_point_px: np.ndarray, R_cam_from_world: np.ndarray,
    t_cam_from_world_m: np.ndarray, *, square_pixels: bool = True, focal_prior_px: np.ndarray | None = None,
    focal_prior_rel_std: np.ndarray | None = None, shape_std_m: float = 0.1, group_scale_std: float | None = None,
    focal_bounds_px: np.ndarray | None = None, min_score: float = 0.2, huber: float = 2.5, max_iterations: int = 40,
    tolerance: float = 1e-6, camera_tolerance: float = 2e-5, hold_views: Sequence[int] = (), lens: str = "pinhole",
    principal_point: bool = False, lens_start: np.ndarray | None = None,
    lens_prior_std: tuple[float, float, float] = (0.25, 0.1, 50.0), hold_lens_views: Sequence[int] = (),
    hold_radial_views: Sequence[int] = (), adjust_cameras: bool = True,
) -> BundleResult:
    """Refine focal lengths, rotations, translations and the groups' keypoints (see the module docstring).

    Args:
        detections, lifted: all detections and their lifted poses.
        groups: G arrays of detection rows, each one person in one frame (one detection per view).
        points_world_m: (G, 23, 3) initial keypoints of the groups, world metres.
        fx_px, fy_px: (V,) initial focal lengths.
        principal_point_px: (V, 2) principal points (fixed).
        R_cam_from_world, t_cam_from_world_m: (V, 3, 3), (V, 3) initial extrinsics; camera 0 stays fixed.
        square_pixels: one focal per view (fx = fy) when True.
        focal_prior_px, focal_prior_rel_std: (V,) optional priors on the focal lengths (``inf`` std: none).
        shape_std_m: std of the lifted poses' joints (per coordinate), metres.
        group_scale_std: when given, every group's lifted poses are compared with its keypoints up to a scale
            ``q`` (the lifter's error of that person's size, shared by its views), with the prior
            ``log q ~ N(0, group_scale_std^2)``: the metric scale of the scene is then the (geometric) mean of
            the lifted sizes and a single person's size error no longer pulls the cameras. None: ``q = 1``.
        focal_bounds_px: (V, 2) low and high bound of every focal, pixels (None: a 10-140 degree horizontal
            field of view of an image twice the principal point's x wide). Starting values near or outside
            a bound start inside it (at 90 % of the way to it, in the bounded parameter).
        min_score: keypoints below this 2D confidence are not used.
        huber: Huber threshold in standard deviations.
        max_iterations: LM iterations.
        tolerance: stop when the relative cost decrease is below this.
        camera_tolerance: also stop when the cameras have stopped moving: for ``_STILL_ITERATIONS`` iterations
            in a row no log focal, rotation increment (radians) or translation relative to the cameras' median
            distance from the world origin changed by more than this. 0 turns it off.
        hold_views: views whose focal length and pose stay as given (e.g. views left out of the groups while the
            others are adjusted); the first view not held keeps its pose (the world frame) instead of view 0.
        lens: ``"pinhole"`` (no radial distortion), ``"k1"`` or ``"k1k2"``: the radial coefficients each view
            estimates (OpenCV's, on normalised image coordinates).
        principal_point: whether each view's principal point moves from ``principal_point_px`` too.
        lens_start: (V, 4) starting ``k1, k2, dcx_px, dcy_px`` (the principal point's offset from
            ``principal_point_px``); None: zeros. Held parameters keep these values.
        lens_prior_std: std of the zero-mean priors on k1, on k2 and on the principal point's offset (pixels).
        hold_lens_views: views whose lens parameters stay at ``lens_start`` (e.g. known cameras).
        hold_radial_views: views whose radial terms (k1, k2) alone stay at ``lens_start`` (a view kept a pinhole
            whose principal point is still estimated).
        adjust_cameras: False holds every camera and solves the groups' keypoints (and scales) alone (e.g. to score
            held-out groups with cameras fitted on others).

    Returns:
        :class:`BundleResult` (the last state that lowered the cost).

    Raises:
        CalibrationError: a starting camera, principal point or focal bound is not finite (naming the view),
            or a group has no finite starting keypoint.
    """
    V = len(fx_px)
    if lens not in ("pinhole", "k1", "k1k2"):
        raise ValueError(f"bundle_adjust: lens must be 'pinhole', 'k1' or 'k1k2', got {lens!r}")
    pp = np.asarray(principal_point_px, dtype=np.float64)
    fx0, fy0 = np.asarray(fx_px, dtype=np.float64), np.asarray(fy_px, dtype=np.float64)
    R_init = np.asarray(R_cam_from_world, dtype=np.float64)
    t_init = np.asarray(t_cam_from_world_m, dtype=np.float64)
    bounds = focal_bounds_from_fov(2.0 * pp[:, 0]) if focal_bounds_px is None else np.asarray(focal_bounds_px, float)
    check_start(fx0, fy0, pp, bounds, R_init, t_init)
    setup = bundle_setup(detections, lifted, groups, points_world_m, pp, bounds, square_pixels=square_pixels,
                   focal_prior_px=focal_prior_px, focal_prior_rel_std=focal_prior_rel_std, shape_std_m=shape_std_m,
                   group_scale_std=group_scale_std, min_score=min_score, huber=huber,
                   lens=lens != "pinhole" or principal_point or lens_start is not None, lens_prior_std=lens_prior_std)
    prob = setup.prob
    cams = start_cameras(prob, fx0, fy0, t_init, np.log(bounds), lens_start)
    held = np.zeros(V, bool)
    held[list(hold_views)] = True
    free = free_parameters(prob, held, adjust_cameras, lens, principal_point, hold_lens_views, hold_radial_views)
    outcome = _iterate(prob, (cams, R_init.copy(), setup.points, np.zeros(prob.G)), free, t_init, huber=huber,
                       max_iterations=max_iterations, tolerance=tolerance, camera_tolerance=camera_tolerance)
    return _result(setup, outcome, free, held, np.log(bounds), pp)


def _iterate(prob: _Problem, start: tuple, free: np.ndarray, t_init: np.ndarray, *, huber: float,
             max_iterations: int, tolerance: float, camera_tolerance: float):
    """Levenberg-Marquardt from ``start`` (cameras (V, nc), rotations (V, 3, 3), keypoints (G, 23, 3) metres, log
    group scales (G,)) over the ``free`` (V, nc) camera parameters; stops early once the cameras stay still
    (``camera_tolerance``, translations relative to the median distance of ``t_init`` (V, 3) from the origin).

    Raises:
        CalibrationError: the starting cost is not finite.
    """
    nf = _focal_count(prob)
    scale_m = max(float(np.median(np.linalg.norm(t_init, axis=1))), 1e-3)
    if not free.any():
        camera_tolerance = 0.0  # the cameras never move: only the cost ends the iterations
    still = 0

    def linearize(state):
        cams, R0, X, log_q = state
        Hcc, Hcp, Hpp, gc, gp, cost, w_obs = _normal_equations(prob, cams, R0, X, log_q, free)
        return (Hcc, Hcp, Hpp, gc, gp, w_obs), cost

    def trial(state, system, lam):
        cams, R0, X, log_q = state
        step = _damped_step(prob, *system[:5], lam, cams, R0, X, log_q, huber)
        if step is None:  # a singular system or non-finite values: refused like a cost increase
            return state, np.inf
        return (step[0], R0, step[1], step[2]), step[3]

    def accepted(old, new):
        nonlocal still
        moved = _camera_step(prob, old[0], new[0], nf, scale_m)
        still = still + 1 if moved < camera_tolerance else 0
        # fold the rotation increment into R0 so the increment parameters stay near zero
        cams = new[0].copy()
        R0 = rotvec_to_rotmat(cams[:, nf : nf + 3]) @ new[1]
        cams[:, nf : nf + 3] = 0.0
        return (cams, R0, new[2], new[3]), still >= _STILL_ITERATIONS

    try:
        return levenberg_marquardt(linearize, trial, start, max_iterations=max_iterations, damping=_DAMPING,
                                   stop=Stop(tolerance), accepted=accepted)
    except FloatingPointError:
        raise CalibrationError("bundle adjustment: the starting cost is not finite (non-finite keypoints or "
                               "poses)") from None


def _result(setup: BundleSetup, outcome, free: np.ndarray, held: np.ndarray, log_bounds: np.ndarray,
            pp: np.ndarray) -> BundleResult:
    """The :class:`BundleResult` of the last accepted state: cameras, keypoints, stds (a focal at a bound:
    undetermined, inf), per-view reprojection rms and status, each detection's error in stds."""
    prob, V = setup.prob, setup.prob.V
    cams, R0, X, log_q = outcome.state
    cost, w_obs = outcome.cost, outcome.system[5]
    nf = _focal_count(prob)
    dlogf = _log_focal(prob, cams[:, :nf])[1][:, 0]
    params_std = camera_std(prob, cams, R0, X, log_q, free, w_obs)
    f_std = params_std[:, 0] * dlogf  # std of log f = std of u times d log f / d u
    lens_std = np.where(free[:, nf + 6 :], params_std[:, nf + 6 :], np.nan) if prob.lens else np.full((V, 4), np.nan)
    fx, fy, R, t = _unpack(prob, cams, R0)
    status = _view_status(prob, np.log(fx), log_bounds, None, None)
    # a focal at a bound of its range is not determined by the data (the bounded parameterization's derivative
    # vanishes there, and with it the std it would report): undetermined, not +- 0
    f_std = np.where(status == "focal_at_bound", np.inf, np.where(held, np.nan, f_std))
    r_obs, _, _, _, (_, _, _, _, P) = _residuals(prob, cams, R0, X, log_q)
    err_px = np.linalg.norm(r_obs / prob.o_w[:, None], axis=1)
    inl = w_obs >= 1.0
    rms = np.array([np.sqrt(np.mean(err_px[(prob.o_view == v) & inl] ** 2)) if np.any((prob.o_view == v) & inl)
                    else np.nan for v in range(V)])
    status = np.where(held, "held", _view_status(prob, np.log(fx), log_bounds, P[:, 2], inl))
    detection_error = _median_per_detection(err_px / setup.sigma_px[setup.observed], setup.observed,
                                            setup.detections)
    logger.info("bundle adjustment: %d groups, %d keypoints, %d iterations (%d steps refused), cost %.4g, rms %s px",
                prob.G, len(err_px), outcome.iterations, outcome.refused, cost, np.round(rms, 2))
    if (status != "ok").any():
        logger.warning("bundle adjustment: views %s end %s", np.flatnonzero(status != "ok").tolist(),
                       status[status != "ok"].tolist())
    lens_values = _lens(prob, cams)
    distortion = np.zeros((V, 5))
    distortion[:, :2] = lens_values[:, :2]
    return BundleResult(fx, fy, R, t, X, f_std, rms, float(inl.mean()) if len(inl) else 0.0, outcome.iterations,
                        outcome.converged, np.exp(log_q), status, outcome.refused, float(cost), detection_error,
                        distortion, pp + lens_values[:, 2:], lens_std)


def _camera_step(prob: _Problem, cams: np.ndarray, new_cams: np.ndarray, nf: int, scale_m: float) -> float:
    """Largest change of a camera parameter in one step: log focal, rotation increment (radians), translation
    relative to ``scale_m``."""
    log_f_change = np.abs(_log_focal(prob, new_cams[:, :nf])[0] - _log_focal(prob, cams[:, :nf])[0]).max()
    rotation_change = np.abs(new_cams[:, nf : nf + 3]).max()
    translation_change = np.abs(new_cams[:, nf + 3 : nf + 6] - cams[:, nf + 3 : nf + 6]).max() / scale_m
    return float(max(log_f_change, rotation_change, translation_change))


def _median_per_detection(values: np.ndarray, detection: np.ndarray, count: int) -> np.ndarray:
    """(count,) median of ``values`` ((N,)) per index of ``detection`` ((N,) in [0, count)); NaN where none."""
    if len(values) == 0:
        return np.full(count, np.nan)
    medians = np.asarray(ndimage.median(values, labels=detection, index=np.arange(count)), dtype=np.float64)
    return np.where(np.bincount(detection, minlength=count) > 0, medians, np.nan)  # scipy gives garbage for none


def _damped_step(prob, Hcc, Hcp, Hpp, gc, gp, lam, cams, R0, X, log_q, huber):
    """One damped Gauss-Newton step and its cost; None when the system is singular or anything is non-finite."""
    try:
        with np.errstate(all="ignore"):
            dc, dp, dq, _ = _solve(Hcc, Hcp, Hpp, gc, gp, lam)
            if not (np.isfinite(dc).all() and np.isfinite(dp).all() and np.isfinite(dq).all()):
                return None
            new_cams, new_X, new_q = cams + dc, X + dp, log_q + dq
            r_obs, r_shape, r_prior, r_scale, _ = _residuals(prob, new_cams, R0, new_X, new_q)
            new_cost = _robust_cost(r_obs, r_shape, r_prior, r_scale, huber)
    except np.linalg.LinAlgError:
        return None
    if not np.isfinite(new_cost):
        return None
    return new_cams, new_X, new_q, new_cost


def _view_status(prob: _Problem, log_fx, log_bounds, depth_m, inlier) -> np.ndarray:
    """(V,) status of every view (see :class:`BundleResult`); only the focal bound without ``depth_m``."""
    status = np.full(prob.V, "ok", dtype=object)
    margin = 0.02 * (log_bounds[:, 1] - log_bounds[:, 0])
    status[(log_fx <= log_bounds[:, 0] + margin) | (log_fx >= log_bounds[:, 1] - margin)] = "focal_at_bound"
    if depth_m is None:
        return status.astype(str)
    for v in range(prob.V):
        mine = prob.o_view == v
        if not mine.any():
            continue
        if np.mean(depth_m[mine] <= 1e-6) > 0.5:
            status[v] = "behind_camera"
        elif not inlier[mine].any():
            status[v] = "no_inliers"
    return status.astype(str)
