"""Initial extrinsics (and multi-view focal lengths) of all views from lifted 3D poses (the paper's III-B).

Steps (each in its own module):

1. relative rotations from Procrustes alignment of lifted poses over all candidate detection pairs of each
   frame, with a consensus over many frames, then rotation averaging (camera 0 = identity)
   (:mod:`.rotation_consensus`); views outside the largest connected part of the view graph are named
   (:mod:`.view_graph`);
2. root positions per detection by a translation-only PnP, then one solve of all translations *and* focal
   lengths from the candidate pairs (linear, then with a size factor per pair for the lifter's per-person size
   errors), Cauchy-reweighted so wrong pairs drop out (:mod:`.translations`); repeated a few times because the
   roots depend on the focal lengths;
3. cross-view groups (one person in one frame) from the consistent pairs (:mod:`.matching`);
4. a bundle adjustment over focal lengths, rotations, translations and the groups' keypoints, with the lifted
   poses as a shape prior up to a size factor per group (:mod:`.bundle`): this recovers the focal
   lengths that single views cannot observe (level or straight-down cameras) and removes the bias of the linear
   solve; views the linear solve cannot see start from a resection or the other views' field of view
   (:mod:`.blind_views`);
5. the final world frame: Z up, floor at z = 0 from the people's feet and trunks, standing or not
   (:mod:`.floor`); when the people give no floor the cameras stay in camera 0's frame, labelled so
   (``ExtrinsicsDiagnostics.world_frame``).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping, Sequence

import numpy as np

from humancal.calibration.bundle import focal_bounds_from_fov
from humancal.calibration.extrinsics_bundle import bundle_stage
from humancal.calibration.extrinsics_config import ExtrinsicsConfig, ExtrinsicsDiagnostics, ExtrinsicsEstimate
from humancal.calibration.extrinsics_report import group_table, pair_table, per_view_table
from humancal.calibration.extrinsics_start import (
    Problem,
    blind_view_start,
    cameras_of,
    initial_points,
    linear_start,
    matched_groups,
    numerical_stage,
    require_finite,
)
from humancal.calibration.floor import NoFloorError, align_to_floor
from humancal.calibration.intrinsics import IntrinsicsEstimate
from humancal.calibration.known_cameras import anchor_to_known, known_rig_estimate, with_known_intrinsics
from humancal.calibration.lens import lens_step
from humancal.calibration.types import CalibrationError, LiftedPoses, check_lifted, hip_midpoints
from humancal.calibration.view_repair import RepairInputs, calibration_adjuster, check_and_repair_views
from humancal.calibration.world_scale import body_size_ratio, people_scale_factor
from humancal.camera import Camera, CameraRig
from humancal.lifter.pose_cues import standing_score
from humancal.tables.detections import DenseDetections

__all__ = ["estimate_extrinsics"]

logger = logging.getLogger(__name__)


def _check_inputs(detections: DenseDetections, lifted: LiftedPoses, intrinsics: Sequence[IntrinsicsEstimate]) -> int:
    check_lifted(detections, lifted)
    V = len(intrinsics)
    if V < 2:
        raise CalibrationError(
            f"extrinsics need at least two views, got {V}: a single camera has no relative pose to estimate"
        )
    if [e.view for e in intrinsics] != list(range(V)):
        raise ValueError(f"intrinsics must be given for views 0..{V - 1} in order, got {[e.view for e in intrinsics]}")
    if len(detections) and (detections.view.min() < 0 or detections.view.max() >= V):
        raise ValueError(f"detections name views outside 0..{V - 1}")
    empty = [v for v in range(V) if not np.any(detections.view == v)]
    if empty:
        raise CalibrationError(f"views {empty} have no detections: their cameras cannot be calibrated")
    return V


def _initial_focals(intrinsics, config):
    """Initial focal lengths, their prior std (inf: no prior) and the image diagonals.

    A well-conditioned single-view focal is kept; an ill-conditioned or missing one starts from the median
    (relative to the image diagonal) of the plausible single-view values, or the diagonal when there is none:
    the linear solve and the bundle adjustment then determine it from the other views.
    """
    diag = np.array([np.hypot(e.width_px, e.height_px) for e in intrinsics])
    f = np.array([np.sqrt(e.fx_px * e.fy_px) for e in intrinsics])
    ok = np.array([e.status == "ok" for e in intrinsics])
    plausible = np.isfinite(f) & (f > 0.3 * diag) & (f < 3.0 * diag)
    ref = ok & plausible if (ok & plausible).any() else plausible
    typical = float(np.median(f[ref] / diag[ref])) if ref.any() else 1.0
    f = np.where(ok & np.isfinite(f), f, typical * diag)
    lo, hi = config.focal_range_rel
    f = np.clip(f, lo * diag, hi * diag)
    rel = np.array([max(e.focal_rel_uncertainty, config.single_view_min_rel_std) for e in intrinsics])
    return f, np.where(ok, rel, np.inf), diag


def estimate_extrinsics(
    detections: DenseDetections,
    lifted: LiftedPoses,
    intrinsics: Sequence[IntrinsicsEstimate],
    config: ExtrinsicsConfig | None = None,
    *,
    view_names: Sequence[str] | None = None,
    known: Mapping[int, Camera] | None = None,
) -> ExtrinsicsEstimate:
    """Extrinsics of all views, with focal lengths refined (and recovered where single views fail).

    Args:
        detections: dense 2D detections of all views and frames.
        lifted: the lifted 3D pose of every detection (row-aligned), in camera frames or in the lifter's crop
            frames (``box_centre_px`` given; turned into camera frames with the current focal lengths).
        intrinsics: the single-view estimates of :func:`~humancal.calibration.intrinsics.estimate_intrinsics`,
            one per view in view order (``status`` ``"no_upright"`` allowed: its focal is recovered here).
        config: settings; defaults to :class:`ExtrinsicsConfig`.
        view_names: the views' names in view order (e.g. camera folders), used in the error messages.
        known: cameras the user knows, by view (pinholes, :mod:`.known_cameras`): all views known, they are
            returned as given with their agreement with the people; some, the others are calibrated around them
            and the world is theirs.

    Returns:
        :class:`ExtrinsicsEstimate`: cameras in the world frame (Z up, floor z = 0 unless ``align_floor`` is off
        or the people give no floor; camera 0's frame otherwise, see ``diagnostics.world_frame``), metres.

    Raises:
        CalibrationError: fewer than two views, a view without detections, views sharing no matched people
            with the others (all views outside the largest connected part of the view graph are named), a
            numerical failure (naming the stage and, where known, the views). Finding no floor is not an error
            (``diagnostics.world_frame``).
        ValueError: inconsistent inputs.
    """
    config = config or ExtrinsicsConfig()
    V = _check_inputs(detections, lifted, intrinsics)
    view_names = _checked_view_names(view_names, V)
    known = dict(known or {})
    if sorted(known) == list(range(V)):
        return known_rig_estimate(detections, lifted, CameraRig.from_cameras([known[v] for v in range(V)]), config)
    if known:
        intrinsics = with_known_intrinsics(intrinsics, known)
    rng = np.random.default_rng(config.seed)
    timings: dict[str, float] = {}
    f0, prior_rel, diag = _initial_focals(intrinsics, config)
    pp = np.array([e.K[:2, 2] for e in intrinsics])
    widths = np.array([float(e.width_px) for e in intrinsics])
    problem = Problem(detections, lifted, pp, focal_bounds_from_fov(widths, config.fov_range_deg), f0, prior_rel,
                       diag, config)

    start = linear_start(problem, V, widths, rng, view_names, timings)
    clock = time.perf_counter()
    groups = matched_groups(problem, start, rng)
    f, t_init, resected = blind_view_start(problem, start, groups)
    points = initial_points(groups, start.lifted_cam, np.nan_to_num(start.roots.T_cam_m), detections.view, start.R,
                             t_init)
    bundled = bundle_stage(problem, start, groups, f, t_init, points, resected, intrinsics, rng, timings)
    timings["bundle"] = time.perf_counter() - clock - timings.get("regroup", 0.0)  # the adjustments alone
    ba, groups, repair, inputs = _view_stage(problem, bundled.ba, bundled.groups, intrinsics, timings)
    refined = _lens_and_scale(problem, ba, groups, inputs, repair, known, timings)

    clock = time.perf_counter()
    R_final, t_final, floor, floor_problem, people = _world_frame(refined.ba, V, config, align_floor=not known)
    timings["floor"] = time.perf_counter() - clock

    cameras = cameras_of(refined.ba, R_final, t_final, refined.pp, refined.distortion, intrinsics)
    diagnostics = _diagnostics(refined, bundled, groups, start, resected, intrinsics, (floor, floor_problem, people),
                               timings, bool(known), config)
    rows = np.concatenate(groups)
    logger.info("extrinsics: %d views, %d groups over %d of %d frames, timings %s", V, len(groups),
                len(np.unique(refined.detections.frame[rows])), len(np.unique(refined.detections.frame)),
                {k: round(v, 2) for k, v in timings.items()})
    return ExtrinsicsEstimate(cameras, diagnostics)


def _checked_view_names(view_names: Sequence[str] | None, V: int) -> list[str] | None:
    """The views' names as strings (None stays None).

    Raises:
        ValueError: they do not name the ``V`` views.
    """
    if view_names is not None and len(view_names) != V:
        raise ValueError(f"view_names must name the {V} views in order, got {len(view_names)} names")
    return None if view_names is None else [str(n) for n in view_names]


def _view_stage(problem: Problem, ba, groups: list[np.ndarray], intrinsics: Sequence[IntrinsicsEstimate],
                timings: dict[str, float]):
    """Step 4's view check (timed as ``"views"``): every view's agreement with the others, disagreeing views
    repaired (:mod:`.view_repair`).

    Returns:
        ``(ba, groups, repair, inputs)``: the checked rig's bundle adjustment and groups, the repair's outcome and
        the check's :class:`~humancal.calibration.view_repair.RepairInputs`.
    """
    detections, lifted, pp, config = problem.detections, problem.lifted, problem.pp, problem.config
    V = len(intrinsics)
    clock = time.perf_counter()
    adjust_any = calibration_adjuster(detections, lifted, pp, problem.bounds, problem.f0, problem.prior_rel, config)
    with numerical_stage("view agreement"):
        inputs = RepairInputs(detections, lifted, pp, np.array([(e.width_px, e.height_px) for e in intrinsics]),
                              problem.bounds, adjust_any, config.agreement(), config.regroup_max_frames or 150)
        ba, groups, repair = check_and_repair_views(ba, groups, inputs, repair=config.repair_views)
    require_finite(np.c_[ba.fx_px, ba.fy_px, ba.R_cam_from_world.reshape(V, -1), ba.t_cam_from_world_m],
                    "view repair")
    timings["views"] = time.perf_counter() - clock
    return ba, groups, repair, inputs


@dataclasses.dataclass(frozen=True)
class _Refined:
    """The rig after the lens step, the people's metric scale and the anchoring to the known cameras.

    Attributes:
        ba: the bundle adjustment (translations and keypoints scaled, metres).
        lens, distortion, lens_std: the lens choice, (V, 5) OpenCV distortion and (V, 4) the std of k1, k2, cx_px,
            cy_px (NaN where not estimated).
        pp: (V, 2) principal points, pixels.
        detections: the detections in the lens's pinhole images.
        repair: the view repair's outcome, its agreement the one of this rig.
        scale: the people's scale factor applied (1 without ``scale_from_limbs``).
    """

    ba: object
    lens: object
    distortion: np.ndarray
    lens_std: np.ndarray
    pp: np.ndarray
    detections: DenseDetections
    repair: object
    scale: float


def _lens_and_scale(problem: Problem, ba, groups: list[np.ndarray], inputs: RepairInputs, repair,
                    known: dict[int, Camera], timings: dict[str, float]) -> _Refined:
    """The lens step (timed as ``"lens"``), the metric scale from the people's limbs, and with known cameras the
    rig moved onto them (their world and, two or more, their scale)."""
    config, lifted, f0, prior_rel = problem.config, problem.lifted, problem.f0, problem.prior_rel
    clock = time.perf_counter()
    with numerical_stage("lens"):
        ba, lens, distortion, lens_std, pp, detections, repair = lens_step(
            ba, groups, problem.detections, lifted, problem.pp, problem.bounds, f0, prior_rel, config, sorted(known),
            inputs, repair)
    timings["lens"] = time.perf_counter() - clock
    adjust_any = calibration_adjuster(detections, lifted, pp, problem.bounds, f0, prior_rel, config)  # lens's images
    scale, _ = people_scale_factor(ba.points_world_m) if config.scale_from_limbs else (1.0, 0)
    ba = dataclasses.replace(ba, t_cam_from_world_m=scale * ba.t_cam_from_world_m,
                             points_world_m=scale * ba.points_world_m)
    if known:  # the known cameras set the world (and, two or more, its scale)
        with numerical_stage("anchoring to the known cameras"):
            ba = anchor_to_known(ba, known, adjust_any, groups)
    return _Refined(ba, lens, distortion, lens_std, pp, detections, repair, scale)


def _diagnostics(refined: _Refined, bundled, groups: list[np.ndarray], start, resected,
                 intrinsics: Sequence[IntrinsicsEstimate], world: tuple, timings: dict[str, float], known: bool,
                 config: ExtrinsicsConfig) -> ExtrinsicsDiagnostics:
    """The :class:`ExtrinsicsDiagnostics` of the final rig: per-view, per-pair and per-group tables, the floor
    (``world``: ``(floor, floor_problem, people)`` of :func:`_world_frame`), the regrouping and the scale."""
    ba, (floor, floor_problem, people) = refined.ba, world
    per_view = per_view_table(ba, intrinsics, start.pairs, start.f_linear, start.blind, resected, refined.distortion,
                              refined.lens_std, refined.pp, refined.repair, config)
    return ExtrinsicsDiagnostics(
        per_view, pair_table(start.pairs, start.residual_deg), group_table(refined.detections, groups), floor,
        ba.inlier_fraction, timings, world_frame=("known_cameras" if known else "floor" if floor is not None
                                                  else "camera_0"),
        floor_problem=floor_problem, people_world_m=people,
        body_size_ratio=body_size_ratio(ba.points_world_m, bundled.lifted_cam, groups),
        mismatched_detections=bundled.dropped, regroup=bundled.regroup_status,
        regroup_detections=bundled.regroup_counts, scale_factor=refined.scale, lens=refined.lens)


def _world_frame(ba, V, config, align_floor: bool = True):
    """Step 5: the bundle adjustment's cameras and people moved to the floor's frame (Z up, floor at z = 0), or
    left in camera 0's frame when ``config.align_floor`` (or ``align_floor``: off when known cameras set the world)
    is off or the people give no floor (said in a warning).

    Returns:
        ``(R_final, t_final, floor, floor_problem, people)``: the cameras' rotations and translations, the
        :class:`~humancal.calibration.floor.FloorAlignment` (None: no floor), why no floor was found (None when one
        was, or when not asked for) and the groups' (G, 3) hip midpoints, all in the returned world frame.
    """
    R_final, t_final = ba.R_cam_from_world, ba.t_cam_from_world_m
    floor, floor_problem = None, None
    if config.align_floor and align_floor:
        # standing from the reconstructed (triangulated) keypoints: body-internal, camera-free
        standing = standing_score(ba.points_world_m)
        with numerical_stage("floor alignment"):
            try:
                floor = align_to_floor(ba.points_world_m, standing, R_final[0],
                                       upright_threshold=config.upright_threshold)
            except NoFloorError as error:  # the cameras hold: keep camera 0's frame and say so
                floor_problem = str(error)
                logger.warning("no floor found (%s): the cameras are returned in camera 0's frame", error)
        if floor is not None:
            R_final, t_final = floor.apply_to_camera(R_final, t_final)
    people = hip_midpoints(ba.points_world_m)
    if floor is not None:
        people = (people - floor.origin_old_m) @ floor.Q_new_from_old.T
        require_finite(np.c_[R_final.reshape(V, -1), t_final], "floor alignment")
    return R_final, t_final, floor, floor_problem, people
