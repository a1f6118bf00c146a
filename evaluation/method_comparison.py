"""The paper's regimes side by side on one sequence: the same detections and association, the cameras and the prior
changed one at a time (the rows of the paper's Tables; ``docs/refinement.md``).

Methods (metric-table names; "init" cameras are the pipeline's self-calibrated ``extrinsics``). Every row whose
cameras move starts, as the pipeline does, from a bundle adjustment of its starting cameras on the triangulated
joints (``BodyFitConfig.bundle_start``), except ``int_ext_no_bundle``:

=================== ======================================================== =========================== ============
method              cameras                                                  refined in the fit          prior
=================== ======================================================== =========================== ============
``int_ext``         init                                                     focal + extrinsics          motion prior
``ext``             init extrinsics with the true intrinsics (focal known)   extrinsics                  motion prior
``gt_cameras``      true (association redone with them)                      no                          motion prior
``init``            init                                                     no                          motion prior
``separate``        init, bundle-adjusted on the triangulated joints first   no                          motion prior
``per_frame_prior`` init                                                     focal + extrinsics          per-frame
``no_prior``        init                                                     focal + extrinsics          none
``no_local_linear`` / ``basic_gru`` / ``no_skip``: as ``int_ext`` with the prior variant trained without the
local-linear term / with one-directional GRUs / without the skip connection (only where their weights exist).
=================== ======================================================== =========================== ============

``int_ext_known_pp`` is not one of the paper's rows: it measures what the principal point, which every other
self-calibrated row holds at the image centre, costs on this sequence (ground truth in a diagnostic row only).
``convention_floor`` is not a fit: the cameras that the self-calibration's convention (principal points at the
image centres, one focal length per view) allows at best, fitted to exact projections of the true 3D joints
(:func:`evaluation.calibration_floor.self_calibration_floor`; ground truth in a diagnostic row only). Camera rows
only; no calibration from detections is expected below it. ``int_ext_no_bundle`` is not one of the paper's rows
either: ``int_ext`` without the bundle-adjusted start, the joint refinement straight from the init cameras (the
paper's schedule, and the pipeline's until the bundle start was chosen).

Every method gets the rows of :func:`evaluation.body_metrics.camera_and_body_rows`: the body rows, its fitted
keypoints' reprojection error named ``fit_reprojection_error_px`` (``reprojection_error_px`` is the camera row's name).
Methods whose cameras differ from both the pipeline's init (whose camera rows are the metric table's ``init``
rows) and the truth get the camera rows of :func:`evaluation.camera_metrics.camera_metrics` too
(``focal_error_pct``, ``position_error_mm``, ``angle_error_deg``, ``reprojection_error_px``: the definitions of
the ``init`` rows, computed for the cameras the method ended with).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from evaluation.body_metrics import camera_and_body_rows
from evaluation.calibration_floor import self_calibration_floor
from evaluation.camera_metrics import camera_metrics
from evaluation.protocols import metrics_table
from humancal.association import associate, to_associations_table, to_skeletons_table
from humancal.body import BodyModel
from humancal.camera import Camera, CameraRig
from humancal.datasets.sequences import SequenceSpec
from humancal.fitting import BodyFitConfig, body_observations, bundle_adjust_on_joints, fit_bodies
from humancal.lifter import LiftedPoses
from humancal.prior import MotionVAE
from humancal.tables.detections import DenseDetections

__all__ = ["METHODS", "Method", "method_metric_table"]


@dataclass(frozen=True)
class Method:
    """One regime: where the cameras start (``init``, ``gt``, ``gt_intrinsics``, ``gt_principal_point``,
    ``bundle``; ``convention_floor``: no fit, see the module docstring), which of their parameters the fit moves
    (``fixed``, ``ext``, ``int_ext``), the prior variant (None: no prior) and whether moving cameras start from a
    bundle adjustment (``BodyFitConfig.bundle_start``)."""

    cameras: str
    regime: str
    prior: str | None = "motion_prior"
    bundle_start: bool = True


METHODS: dict[str, Method] = {
    "int_ext": Method("init", "int_ext"),
    "int_ext_known_pp": Method("gt_principal_point", "int_ext"),
    "ext": Method("gt_intrinsics", "ext"),
    "gt_cameras": Method("gt", "fixed"),
    "init": Method("init", "fixed"),
    "separate": Method("bundle", "fixed"),
    "int_ext_no_bundle": Method("init", "int_ext", bundle_start=False),
    "convention_floor": Method("convention_floor", "fixed", prior=None),
    "per_frame_prior": Method("init", "int_ext", "per_frame"),
    "no_prior": Method("init", "int_ext", None),
    "no_local_linear": Method("init", "int_ext", "no_local_linear"),
    "basic_gru": Method("init", "int_ext", "unidirectional"),
    "no_skip": Method("init", "int_ext", "no_skip"),
}
"""Every method of the module docstring."""


def _with_true_intrinsics(cameras: CameraRig, gt_cameras: CameraRig) -> CameraRig:
    return CameraRig.from_cameras([Camera(g.K, c.R_cam_from_world, c.t_cam_from_world_m, c.width_px, c.height_px,
                                          g.distortion) for c, g in zip(cameras, gt_cameras)])


def _with_true_principal_points(cameras: CameraRig, gt_cameras: CameraRig) -> CameraRig:
    moved = []
    for c, g in zip(cameras, gt_cameras):
        K = c.K.copy()
        K[:2, 2] = g.K[:2, 2]
        moved.append(Camera(K, c.R_cam_from_world, c.t_cam_from_world_m, c.width_px, c.height_px, c.distortion))
    return CameraRig.from_cameras(moved)


def _true_joints_m(gt_poses3d: pd.DataFrame) -> np.ndarray:
    """(N, 3) the valid, finite joints of a ``poses3d`` table, metres."""
    valid = gt_poses3d[gt_poses3d["valid"]] if "valid" in gt_poses3d else gt_poses3d
    points = valid[["x_m", "y_m", "z_m"]].to_numpy(dtype=np.float64)
    return points[np.isfinite(points).all(axis=1)]


def method_metric_table(spec: SequenceSpec, *, methods: list[str], priors: Callable[[str], MotionVAE | None],
                        body: BodyModel, config: BodyFitConfig, fps: float, dense: DenseDetections,
                        lifted: LiftedPoses, detections: pd.DataFrame, associations: pd.DataFrame, skeletons3d: pd.DataFrame,
                        cameras: CameraRig, gt_associations: pd.DataFrame, gt_poses3d: pd.DataFrame,
                        gt_cameras: CameraRig, gt_motions: pd.DataFrame | None, failed_checks: str | None = None,
                        log: Callable[[str], None] | None = None) -> pd.DataFrame:
    """Fit and score each of ``methods`` (keys of :data:`METHODS`) on one sequence.

    Args:
        methods: which methods; a prior variant whose weights ``priors`` cannot give (returns None for a variant
            other than None) is skipped with a log line.
        priors: the prior of a variant name.
        config: the pipeline's fit settings; each method changes only ``cameras``.
        dense, lifted: the detections and their lifted poses (``humancal.lifter.lifted_from_table`` of the
            ``detections`` asset), for the fits and the association with the true cameras.
        detections: the 2D detections; associations, skeletons3d: the pipeline's association (init cameras).
        cameras: the init cameras; failed_checks: the checks they failed (carried on rows that start from them).
    """
    say = log or (lambda message: None)
    gt_association: tuple[pd.DataFrame, pd.DataFrame] | None = None
    parts = []
    for name in methods:
        method = METHODS[name]
        prior = priors(method.prior) if method.prior is not None else None
        if method.prior is not None and prior is None:
            say(f"{name}: no weights for the prior variant {method.prior!r}: skipped (train it with "
                f"`humancal train prior --variant {method.prior}`)")
            continue
        start = time.perf_counter()
        if method.cameras == "convention_floor":
            joints = _true_joints_m(gt_poses3d)
            if len(gt_cameras) < 2 or len(joints) < 6:
                say(f"{name}: needs 2 true cameras and 6 true joints, got {len(gt_cameras)} and {len(joints)}: skipped")
                continue
            floor = self_calibration_floor(gt_cameras, joints)
            rows = camera_metrics(floor["cameras"], gt_cameras, detections, gt_associations)
            say(f"{name}: {time.perf_counter() - start:.1f} s")
            parts.append(metrics_table(spec.dataset, spec.sequence, name, rows, None))
            continue
        people, skeletons, used, failed = associations, skeletons3d, cameras, failed_checks
        if method.cameras == "gt":
            if gt_association is None:
                result = associate(dense, lifted, CameraRig.of(gt_cameras))
                gt_association = (to_associations_table(result, spec.sequence),
                                  to_skeletons_table(result, spec.sequence))
            (people, skeletons), used, failed = gt_association, gt_cameras, None
        elif method.cameras == "gt_intrinsics":
            used = _with_true_intrinsics(cameras, gt_cameras)
        elif method.cameras == "gt_principal_point":
            used = _with_true_principal_points(cameras, gt_cameras)
        observations, _ = body_observations(dense, people, skeletons, len(used))
        rig = CameraRig.of(used)
        if method.cameras == "bundle":
            rig = bundle_adjust_on_joints(observations, rig, config, regime="int_ext").cameras
        fit = fit_bodies(body, observations, rig, prior,
                         config.replace(cameras=method.regime, bundle_start=method.bundle_start), fps=fps)
        seconds = time.perf_counter() - start
        say(f"{name}: {seconds:.1f} s")
        rows = camera_and_body_rows(
            spec, motions=fit.motions.to_table(spec.sequence), cameras=fit.cameras, seconds=seconds,
            associations=people, detections=detections, gt_associations=gt_associations, gt_poses3d=gt_poses3d,
            gt_cameras=gt_cameras, gt_motions=gt_motions, body=body, fps=fps,
            with_cameras=method.cameras in ("gt_intrinsics", "gt_principal_point", "bundle") or method.regime != "fixed")
        parts.append(metrics_table(spec.dataset, spec.sequence, name, rows, failed))
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()
