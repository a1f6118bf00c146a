"""Step 4 of the extrinsics (:func:`~humancal.calibration.extrinsics.estimate_extrinsics`): the bundle adjustment
from the best start, the groups found again with its cameras, mismatched detections taken out, and crop-frame poses
turned again at its focal lengths."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from functools import partial

import numpy as np

from humancal.calibration.bundle import bundle_adjust
from humancal.calibration.extrinsics_start import (
    LinearStart,
    Problem,
    camera_matrices,
    cameras_of,
    initial_points,
    numerical_stage,
    require_finite,
)
from humancal.calibration.matching import drop_mismatched_detections, spread_groups
from humancal.calibration.regroup import regroup_with_cameras
from humancal.calibration.translations import root_positions, solve_focals_translations
from humancal.calibration.types import CalibrationError, LiftedPoses

__all__ = ["Bundled", "bundle_stage"]

logger = logging.getLogger("humancal.calibration.extrinsics")


@dataclass(frozen=True)
class Bundled:
    """Step 4's outcome: the bundle adjustment, its groups and the camera-frame poses it used, and what happened
    on the way (:class:`ExtrinsicsDiagnostics` ``regroup``, ``regroup_detections``, ``mismatched_detections``)."""

    ba: object
    groups: list
    lifted_cam: LiftedPoses
    regroup_status: str
    regroup_counts: tuple[int, int]
    dropped: int


def bundle_stage(problem: Problem, start: LinearStart, groups, f, t_init, points, resected, intrinsics, rng,
                  timings: dict) -> Bundled:
    """Step 4: the bundle adjustment from the best start, the groups found again with its cameras, mismatched
    detections taken out, and the crop-frame poses turned again at its focal lengths, each followed by another
    adjustment."""
    detections, pp, config, R = problem.detections, problem.pp, problem.config, start.R
    lifted, lifted_as_given, f_frame, V = start.lifted_cam, problem.lifted, start.f_frame, len(f)

    def adjust(f_start, R_start, t_start, points_start, iterations, lifted_cam=lifted):
        # ``groups`` is read at each call: the mismatch rounds below replace it
        return bundle_adjust(
            detections, lifted_cam, groups, points_start, f_start, f_start, pp, R_start, t_start,
            square_pixels=config.square_pixels, focal_prior_px=problem.f0, focal_prior_rel_std=problem.prior_rel,
            shape_std_m=config.shape_std_m, group_scale_std=config.person_scale_std, focal_bounds_px=problem.bounds,
            max_iterations=iterations,
        )

    with numerical_stage("bundle adjustment"):
        unseen = start.blind & ~resected
        if unseen.any() and config.blind_start_fov_deg:
            f, t_init, points, started = _best_start(partial(adjust, R_start=R), f, t_init, points, unseen,
                                                     problem.diag, problem.bounds, detections, lifted, groups,
                                                     start.rows_a[start.sol.inlier], start.rows_b[start.sol.inlier],
                                                     R, pp, config)
            logger.info("views %s: started the bundle adjustment from %s px (%s)", np.flatnonzero(unseen).tolist(),
                        np.round(f[unseen]).tolist(), started)
        ba = adjust(f, R, t_init, points, config.bundle_iterations)
        regroup_status, regroup_counts = "off", (0, 0)
        if config.regroup_max_frames and V == 2:
            # two views: matching by geometry adds an epipolar line, which a wrong pair near it passes; the
            # camera-free matching's pose test is kept (measured: the groups found again were worse in 5 of 6
            # two-view draws of a test scene)
            regroup_status = "off: two views"
        elif config.regroup_max_frames:
            clock_regroup = time.perf_counter()
            groups, points, regroup_status, regroup_counts = _regroup(ba, groups, detections, lifted_as_given, pp,
                                                                      intrinsics, config, rng)
            timings["regroup"] = time.perf_counter() - clock_regroup
            if points is not None:
                ba = adjust(ba.fx_px, ba.R_cam_from_world, ba.t_cam_from_world_m, points, config.bundle_iterations,
                            lifted)
        dropped = 0
        for _ in range(config.mismatch_rounds if config.mismatch_threshold_sigma > 0 else 0):
            kept_groups, kept, n = drop_mismatched_detections(groups, ba.detection_error_sigma,
                                                              config.mismatch_threshold_sigma,
                                                              config.mismatch_max_fraction)
            if n == 0 or len(kept_groups) < 3:
                break
            groups, dropped = kept_groups, dropped + n
            ba = adjust(ba.fx_px, ba.R_cam_from_world, ba.t_cam_from_world_m, ba.points_world_m[kept],
                        config.bundle_iterations)
        if dropped:
            logger.info("bundle adjustment: %d detections reprojected over %.0f stds from their groups (matched to "
                        "the wrong person): taken out and adjusted again, %d groups left", dropped,
                        config.mismatch_threshold_sigma, len(groups))
        for _ in range(3 if lifted_as_given.frame == "crop" else 0):
            if np.max(np.abs(np.log(ba.fx_px / f_frame))) < 0.02:
                break
            # the crop-frame poses were turned into camera frames at focal lengths the bundle adjustment has
            # since moved away from: turn them again at its focal lengths and refine once more from its result
            f_frame = ba.fx_px.copy()
            lifted = lifted_as_given.in_camera_frame(camera_matrices(f_frame, f_frame, pp)[detections.view])
            ba = adjust(ba.fx_px, ba.R_cam_from_world, ba.t_cam_from_world_m, ba.points_world_m,
                        config.bundle_iterations, lifted)
    require_finite(np.c_[ba.fx_px, ba.fy_px, ba.R_cam_from_world.reshape(V, -1), ba.t_cam_from_world_m],
                    "bundle adjustment")
    return Bundled(ba, groups, lifted, regroup_status, regroup_counts, dropped)


def _best_start(adjust, f, t, points, unseen, diag, bounds, detections, lifted, groups, rows_a, rows_b, R, pp,
                config):
    """The start of the bundle adjustment with the lowest cost after a few iterations: the one in hand, or the
    views in ``unseen`` at each of ``config.blind_start_fov_deg`` (diagonal fields of view), with the
    translations and keypoints solved again at those focal lengths (all focal lengths held by a tight prior).

    Returns the chosen focal lengths, translations, keypoints and a description of the start.
    """
    best = (adjust(f, t_start=t, points_start=points, iterations=config.blind_start_iterations).cost, f, t, points, "the other views' field of view")
    tight = np.full(len(f), 1e-3)
    for fov in config.blind_start_fov_deg:
        f_s = np.where(unseen, np.clip(0.5 * diag / np.tan(np.radians(fov) / 2), bounds[:, 0], bounds[:, 1]), f)
        roots_s = root_positions(detections, lifted, camera_matrices(f_s, f_s, pp))
        sol_s = solve_focals_translations(roots_s, detections.view, rows_a, rows_b, R, f_s, tight,
                                          person_scale_std=config.person_scale_std)
        if not np.isfinite(sol_s.t_cam_from_world_m).all():
            continue
        t_s = sol_s.t_cam_from_world_m
        points_s = initial_points(groups, lifted, np.nan_to_num(roots_s.T_cam_m), detections.view, R, t_s)
        try:
            cost = adjust(f_s, t_start=t_s, points_start=points_s, iterations=config.blind_start_iterations).cost
        except CalibrationError:  # a start the bundle adjustment refuses (non-finite keypoints) is no candidate
            continue
        if cost < best[0]:
            best = (cost, f_s, t_s, points_s, f"a {fov:.0f} degree diagonal field of view")
    return best[1], best[2], best[3], best[4]


def _regroup(ba, groups, detections, lifted_as_given, pp, intrinsics, config, rng):
    """The groups found again with the bundle-adjusted cameras (:mod:`.regroup`) when they hold enough more
    detections than the first ones (``regroup_min_gain``). Returns (groups, their starting points (G, 23, 3) or
    None when the first are kept, status, (detections in the first groups, in the new ones))."""
    before = sum(len(g) for g in groups)
    cameras = cameras_of(ba, ba.R_cam_from_world, ba.t_cam_from_world_m, pp, np.zeros((len(pp), 5)), intrinsics)
    try:
        found = regroup_with_cameras(detections, lifted_as_given, cameras, config.regroup_max_frames)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError) as error:  # refused inputs, numerical failure
        logger.warning("regrouping with the bundle-adjusted cameras failed (%s: %s): the first groups are kept",
                       type(error).__name__, error)
        return groups, None, "kept: association failed", (before, 0)
    pick = spread_groups(found.groups, detections, config.max_groups, rng)
    new_groups = [found.groups[i] for i in pick]
    after = sum(len(g) for g in new_groups)
    if after < config.regroup_min_gain * before or after <= before or len(new_groups) < 3:
        logger.info("regrouping with the bundle-adjusted cameras: %d detections in %d groups, against %d in the "
                    "first %d: the first groups are kept", after, len(new_groups), before, len(groups))
        return groups, None, "kept: too few more detections", (before, after)
    logger.info("regrouping with the bundle-adjusted cameras: %d groups (%d detections, %d frames matched), "
                "were %d (%d detections)", len(new_groups), after, found.frames_used, len(groups), before)
    return new_groups, found.points_world_m[pick], "regrouped", (before, after)
