"""Steps 1-3 of the extrinsics (:func:`~humancal.calibration.extrinsics.estimate_extrinsics`), camera-free: the
rotations averaged from the pair rotations, the linear focal lengths and translations, the cross-view groups of
matched people, and where the bundle adjustment starts the views the linear solve cannot see. With the helpers the
stages share (numerical failures named by stage, non-finite views named, the cameras of a bundle adjustment)."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from humancal.calibration.blind_views import blind_views, other_views_focal, resection_pass, translations_from_others
from humancal.calibration.extrinsics_config import ExtrinsicsConfig
from humancal.calibration.matching import groups_from_pairs, spread_groups
from humancal.calibration.rotation_consensus import average_rotations, pairwise_rotations
from humancal.calibration.translations import root_positions, solve_focals_translations
from humancal.calibration.types import CalibrationError, LiftedPoses
from humancal.calibration.view_graph import check_view_graph
from humancal.camera import Camera, CameraRig, intrinsic_matrices
from humancal.tables.detections import DenseDetections

__all__ = ["LinearStart", "Problem", "blind_view_start", "camera_matrices", "cameras_of", "initial_points",
           "linear_start", "matched_groups", "numerical_stage", "require_finite"]

logger = logging.getLogger("humancal.calibration.extrinsics")


def camera_matrices(fx, fy, pp) -> np.ndarray:
    """(V, 3, 3) intrinsic matrices of (V,) focal lengths and (V, 2) principal points, pixels."""
    pp = np.asarray(pp, float).reshape(-1, 2)
    return intrinsic_matrices(fx, fy, pp[:, 0], pp[:, 1])


@contextmanager
def numerical_stage(name: str) -> Iterator[None]:
    """Numerical failures of a step (a singular system, a floating-point error) become a :class:`CalibrationError`
    naming the step."""
    try:
        yield
    except (np.linalg.LinAlgError, FloatingPointError, OverflowError, ZeroDivisionError) as error:
        raise CalibrationError(f"extrinsics, {name}: numerical failure ({type(error).__name__}: {error})") from error


def require_finite(values: np.ndarray, stage: str) -> None:
    """Raise :class:`CalibrationError` naming the views whose row of ``values`` ((V, ...)) is not finite."""
    bad = np.flatnonzero(~np.isfinite(np.asarray(values, dtype=np.float64).reshape(len(values), -1)).all(1))
    if len(bad):
        raise CalibrationError(f"extrinsics, {stage}: views {bad.tolist()} have non-finite parameters")


@dataclass(frozen=True)
class Problem:
    """What every stage of :func:`estimate_extrinsics` reads: the detections, the lifted poses as given (camera or
    crop frames), the principal points (V, 2), the focal bounds (V, 2), the initial focal lengths (V,), their prior
    std (V,; inf: none), the image diagonals (V,), pixels, and the settings."""

    detections: DenseDetections
    lifted: LiftedPoses
    pp: np.ndarray
    bounds: np.ndarray
    f0: np.ndarray
    prior_rel: np.ndarray
    diag: np.ndarray
    config: ExtrinsicsConfig


@dataclass(frozen=True)
class LinearStart:
    """Steps 1-2, camera-free: the averaged rotations and the linear focal lengths and translations.

    Attributes:
        consistent_pairs: pairs the linear solve kept (inliers).
        attempt: 0 (the poses turned at the starting focal lengths) or 1 (at the linear ones).
        R: (V, 3, 3) rotations; residual_deg: per pair, its disagreement with them; pairs: the pair rotations;
            rows_a, rows_b: the detection rows of the candidate pairs used.
        f: (V,) the focal lengths to start from (views the linear solve cannot see: the other views' field of view);
            f_linear: (V,) the linear solution; blind: (V,) the views it cannot see.
        sol: the linear solution (translations, inliers, stds); roots: the root positions at ``f``.
        lifted_cam: the lifted poses in camera frames, turned at ``f_frame`` (V,) where given in crop frames.
    """

    consistent_pairs: int
    attempt: int
    R: np.ndarray
    residual_deg: np.ndarray
    pairs: list
    rows_a: np.ndarray
    rows_b: np.ndarray
    f: np.ndarray
    sol: object
    roots: object
    f_linear: np.ndarray
    blind: np.ndarray
    lifted_cam: LiftedPoses
    f_frame: np.ndarray


def linear_start(problem: Problem, V: int, widths: np.ndarray, rng, view_names, timings: dict) -> LinearStart:
    """Steps 1-2. Crop-frame poses (the lifter's) turn into camera frames by an angle that depends on the focal:
    converted with the initial focal lengths, and once more with the linear solution if it moved them noticeably;
    the second is kept unless it matches far fewer pairs."""
    detections, lifted, pp, config = problem.detections, problem.lifted, problem.pp, problem.config
    f_frame = problem.f0.copy()
    lifted_cam = lifted.in_camera_frame(camera_matrices(f_frame, f_frame, pp)[detections.view])
    attempts = []
    for attempt in range(2 if lifted.frame == "crop" else 1):
        clock = time.perf_counter()
        with numerical_stage("rotations"):
            R, residual_deg, pairs, rows_a, rows_b = _rotations(detections, lifted_cam, V, rng, config, view_names)
        require_finite(R.reshape(V, -1), "rotations")
        timings["rotations"] = timings.get("rotations", 0.0) + time.perf_counter() - clock
        clock = time.perf_counter()
        with numerical_stage("linear focal and translation solve"):
            f, sol, roots, undetermined = _linear(detections, lifted_cam, rows_a, rows_b, R, problem.f0,
                                                  problem.prior_rel, pp, problem.diag, config)
        timings["linear"] = timings.get("linear", 0.0) + time.perf_counter() - clock
        f_linear = f.copy()
        # views the linear solve cannot see (a non-positive focal, one at the end of the range or outside the
        # plausible field of view, or a large data-only std) must not start anything from that value (it is a
        # clamp, not an estimate): they start from the other views' field of view, then a resection
        blind = blind_views(f, sol, undetermined, problem.bounds, problem.diag, config)
        f = np.where(blind, other_views_focal(f, blind, widths, problem.f0, problem.bounds), f)
        attempts.append(LinearStart(int(sol.inlier.sum()), attempt, R, residual_deg, pairs, rows_a, rows_b, f, sol,
                                     roots, f_linear, blind, lifted_cam, f_frame))
        if lifted.frame != "crop" or np.max(np.abs(np.log(f / f_frame))) < 0.05 or attempt == 1:
            break
        f_frame = f.copy()
        lifted_cam = lifted.in_camera_frame(camera_matrices(f_frame, f_frame, pp)[detections.view])
    # the poses turned at the linear focal lengths are kept unless they match far fewer pairs (with wrong rotations
    # the linear focal lengths can be far off, and the poses turned at them worse than at the starting ones)
    chosen = attempts[-1] if attempts[-1].consistent_pairs >= 0.5 * attempts[0].consistent_pairs else attempts[0]
    if len(attempts) > 1:
        logger.info("crop-frame poses turned at the %s focal lengths (consistent pairs: %d at the starting ones, "
                    "%d at the linear ones)", "linear" if chosen.attempt else "starting",
                    attempts[0].consistent_pairs, attempts[1].consistent_pairs)
    return chosen


def _rotations(detections, lifted, V, rng, config, view_names):
    """Consensus pair rotations (hypothesis budget spread over the view pairs) and their average."""
    n_pairs = V * (V - 1) // 2
    per_view_dets = np.bincount(detections.view, minlength=V)
    frames = max(len(np.unique(detections.frame)), 1)
    per_frame = np.maximum(per_view_dets / frames, 1.0)
    budget = config.max_pair_hypotheses / (n_pairs * float(np.mean(per_frame)) ** 2)
    max_frames = int(max(20, min(config.max_frames_per_pair, budget)))
    pairs = pairwise_rotations(detections, lifted, V, rng, max_frames=max_frames,
                               max_pose_error_m=config.max_pose_error_m, threshold_deg=config.rotation_threshold_deg)
    check_view_graph(pairs, V, config.min_pair_support, view_names)
    R, residual_deg = average_rotations(pairs, V, min_support=config.min_pair_support)
    used = [p for p in pairs if p.support >= config.min_pair_support]
    rows_a = np.concatenate([p.rows_a for p in used])
    rows_b = np.concatenate([p.rows_b for p in used])
    return R, residual_deg, pairs, rows_a, rows_b


def _linear(detections, lifted, rows_a, rows_b, R, f0, prior_rel, pp, diag, config):
    """Alternate root positions and the linear focal + translation solve until the focal lengths settle.

    Returns the focal lengths, the last solution, the roots at those focal lengths and the views whose focal the
    last solve left non-positive or non-finite.
    """
    # every view keeps a weak prior so that an unobservable focal stays finite (100 % std)
    lin_prior_rel = np.where(np.isfinite(prior_rel), prior_rel, 1.0)
    f = f0.copy()
    for _ in range(config.linear_iterations):
        roots = root_positions(detections, lifted, camera_matrices(f, f, pp))
        sol = solve_focals_translations(roots, detections.view, rows_a, rows_b, R, f0, lin_prior_rel,
                                        person_scale_std=config.person_scale_std)
        # the roots were computed at f: move at most by a factor 2 per pass (the linearisation is local); a
        # non-positive or non-finite focal says the pairs do not determine that view (not "smaller"): it stays
        undetermined = ~(np.isfinite(sol.focal_px) & (sol.focal_px > 0))
        step = np.where(undetermined, 1.0, np.clip(np.nan_to_num(sol.focal_px / f, nan=1.0), 0.5, 2.0))
        f_new = np.clip(f * step, config.focal_range_rel[0] * diag, config.focal_range_rel[1] * diag)
        converged = np.max(np.abs(np.log(f_new / f))) < 0.005
        f = f_new
        if converged:
            break
    return f, sol, root_positions(detections, lifted, camera_matrices(f, f, pp)), undetermined


def matched_groups(problem: Problem, start: LinearStart, rng) -> list[np.ndarray]:
    """Step 3: cross-view groups (one person in one frame) from the consistent pairs, at most ``max_groups`` spread
    over the capture."""
    detections, config, sol = problem.detections, problem.config, start.sol
    rows_a, rows_b = start.rows_a[sol.inlier], start.rows_b[sol.inlier]
    groups = groups_from_pairs(rows_a, rows_b, detections.view, len(detections))
    if len(groups) < config.max_groups // 2:
        # too few conflict-free people (crowded, static scenes: seated people close together let many wrong pairs
        # through): split the conflicted components instead of dropping them
        groups = groups_from_pairs(rows_a, rows_b, detections.view, len(detections),
                                   pair_cost=sol.residual_m[sol.inlier])
    if len(groups) < 3:
        raise CalibrationError(f"only {len(groups)} people could be matched across views: cannot refine the cameras")
    return [groups[i] for i in spread_groups(groups, detections, config.max_groups, rng)]


def blind_view_start(problem: Problem, start: LinearStart, groups) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The focal lengths and translations the bundle adjustment starts from: the views the linear solve cannot see
    placed by a resection against the people the others place, or kept at the other views' field of view with
    their translation from those people. Returns (f (V,), t (V, 3), resected (V,))."""
    detections, pp, R, sol, blind = problem.detections, problem.pp, start.R, start.sol, start.blind
    lifted, f = start.lifted_cam, start.f
    t_init = sol.t_cam_from_world_m.copy()
    resected = np.zeros(len(f), bool)
    if blind.any():
        with numerical_stage("resection"):
            f_res, t_res, resected = resection_pass(groups, detections, lifted, np.nan_to_num(start.roots.T_cam_m), R,
                                                     t_init, f, pp, problem.bounds, np.flatnonzero(blind))
            f = np.where(resected, f_res, f)
            t_init[resected] = t_res[resected]
            # the rest keep the other views' field of view: their translation from the people those views place
            others = blind & ~resected
            if others.any():
                roots_f = root_positions(detections, lifted, camera_matrices(f, f, pp))
                t_init[others] = translations_from_others(groups, detections, lifted, roots_f.T_cam_m, R, t_init,
                                                           np.flatnonzero(others))[others]
        logger.info("views %s: the linear focal %s is not an estimate (data-only std %s); started from %s px (%s)",
                    np.flatnonzero(blind).tolist(), np.round(start.f_linear[blind]).tolist(),
                    np.round(sol.focal_rel_std_data[blind], 3).tolist(), np.round(f[blind]).tolist(),
                    ["resection" if r else "other views' field of view" for r in resected[blind]])
    logger.info("linear focal std (data only) %s", np.round(sol.focal_rel_std_data, 3).tolist())
    require_finite(t_init, "translations before the bundle adjustment")
    return f, t_init, resected


def initial_points(groups, lifted, roots_T, view, R, t):
    pts = np.zeros((len(groups), lifted.joints_cam_m.shape[1], 3))
    Rt = np.transpose(R, (0, 2, 1))
    for k, g in enumerate(groups):
        world = [Rt[view[d]] @ (lifted.joints_cam_m[d] + roots_T[d]).T - (Rt[view[d]] @ t[view[d]])[:, None]
                 for d in g]
        pts[k] = np.mean(world, axis=0).T
    return pts


def cameras_of(ba, R_cam_from_world, t_cam_from_world_m, pp, distortion, intrinsics) -> CameraRig:
    """The bundle adjustment's focal lengths with the given extrinsics, principal points (V, 2) and lens distortion
    (V, 5), as the rig of cameras of the views' image sizes."""
    return CameraRig.from_cameras([
        Camera(camera_matrices([ba.fx_px[v]], [ba.fy_px[v]], pp[v : v + 1])[0], R_cam_from_world[v],
               t_cam_from_world_m[v], e.width_px, e.height_px, distortion[v])
        for v, e in enumerate(intrinsics)])
