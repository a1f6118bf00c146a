"""Camera calibration metrics against ground-truth cameras (the paper's Table: focal, position, angle, reprojection).

Protocol:

* The estimated rig is brought onto the ground-truth world by the least-squares **similarity** (Umeyama) of the
  camera centres (with two cameras, points one baseline ahead on each optical axis are added so that the
  rotation about the baseline is fixed): :func:`humancal.calibration.rig_alignment.align_rig`.
* ``focal_error_pct``: ``100 |f_est - f_gt| / f_gt`` with ``f = sqrt(fx fy)``.
* ``position_error_mm``: distance between the aligned estimated centre and the true centre.
* ``angle_error_deg``: geodesic angle between the aligned estimated rotation and the true one.
* ``scale_error_pct``: how much larger the estimated world is than the true one, ``100 (1 / s - 1)`` with ``s`` the
  scale of that similarity (negative: too small). The other figures are measured after the alignment, which hides
  the scale; this one shows it (one row for the rig, no per-view rows).
* ``reprojection_error_px``: each ground-truth person (identities from the ground-truth associations: evaluation
  only) is triangulated per frame from all its detections with the estimated cameras (confidence-weighted DLT,
  :func:`humancal.geometry.triangulation.triangulate_dlt`) and reprojected; the mean pixel distance over the
  detected keypoints. ``reprojection_error_gt_cameras_px`` is the same with the ground-truth cameras: the floor
  set by the detections themselves.

Every metric is reported per view (the row's ``view`` column) and as the mean over views (``view`` null).

:func:`centred_principal_point_floor` measures what the convention of the self-calibration (the principal point at the
image centre, the paper's too) costs by itself: each true camera's pose re-estimated, with its principal point moved to
the image centre, from the exact projections of known 3D points (per camera; the whole-rig floor, scored like the
benchmark's rows, is :mod:`evaluation.calibration_floor`).
"""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd

from evaluation.protocols import MetricRow, metrics_table
from humancal.calibration.rig_alignment import Similarity, align_rig
from humancal.camera import Camera, CameraRig
from humancal.geometry.rotations import rotation_distance_deg
from humancal.geometry.triangulation import reprojection_errors_px, triangulate_dlt
from humancal.tables.associations import Associations
from humancal.tables.detections import detections_to_dense
from humancal.tables.pivot import unique_rows

__all__ = ["CameraErrors", "camera_errors", "scale_error_pct", "centred_principal_point_floor", "reprojection_errors_per_view", "camera_metrics", "camera_metrics_table"]

METHOD = "init"


class CameraErrors(dict):
    """Per-view arrays ``focal_error_pct``, ``position_error_mm``, ``angle_error_deg`` and the ``alignment``."""


def camera_errors(estimated: CameraRig, ground_truth: CameraRig) -> CameraErrors:
    """Focal, position and angle errors of every view after the similarity alignment of the centres.

    Returns:
        :class:`CameraErrors` with (V,) arrays and the :class:`~humancal.calibration.rig_alignment.Similarity`.

    Raises:
        ValueError: the rigs differ in size.
    """
    sim: Similarity = align_rig(estimated, ground_truth)
    f_est = np.array([np.sqrt(c.K[0, 0] * c.K[1, 1]) for c in estimated])
    f_gt = np.array([np.sqrt(c.K[0, 0] * c.K[1, 1]) for c in ground_truth])
    aligned = [sim.apply_to_camera(c) for c in estimated]
    pos = np.array([1000.0 * np.linalg.norm(a.center_world_m - g.center_world_m) for a, g in zip(aligned, ground_truth)])
    ang = rotation_distance_deg(np.stack([a.R_cam_from_world for a in aligned]),
                                np.stack([g.R_cam_from_world for g in ground_truth]))
    return CameraErrors(focal_error_pct=100.0 * np.abs(f_est - f_gt) / f_gt, position_error_mm=pos,
                        angle_error_deg=ang, alignment=sim)


def scale_error_pct(alignment: Similarity) -> float:
    """How much larger (%) the estimated world is than the true one, from the similarity that aligns it onto the
    truth (``x_true = s R x_est + t``): ``100 (1 / s - 1)``."""
    return float(100.0 * (1.0 / alignment.scale - 1.0))


def centred_principal_point_floor(ground_truth: CameraRig, points_world_m: np.ndarray) -> dict[str, np.ndarray]:
    """The camera errors that holding the principal point at the image centre causes by itself.

    Each true camera's intrinsics get their principal point moved to the image centre (``width/2, height/2``; focal and
    distortion kept); its pose is then re-estimated (``cv2.solvePnP``, started from the true pose) from the exact,
    noise-free projections of ``points_world_m`` through the true camera, the other cameras and the points held
    true and nothing aligned. It shows how each camera turns to make up for its offset; it is not a bound on the
    benchmark's aligned errors (a whole rig fitted under the convention can turn together and land closer: that
    floor is :func:`evaluation.calibration_floor.self_calibration_floor`).

    Args:
        ground_truth: V true cameras.
        points_world_m: (N, 3) points the cameras see (e.g. the ground-truth joints), metres; N >= 6.

    Returns:
        (V,) arrays: ``offset_px`` (the distance of the true principal point from the centre), ``angle_error_deg``
        and ``position_error_mm`` of the re-estimated pose against the true one (no alignment: the world is the
        true one), and ``residual_px`` (the mean reprojection error left: how visible the offset is in the images).
    """
    X = np.asarray(points_world_m, dtype=np.float64).reshape(-1, 3)
    if len(X) < 6:
        raise ValueError(f"centred_principal_point_floor needs at least 6 points, got {len(X)}")
    out = {k: np.zeros(len(ground_truth)) for k in ("offset_px", "angle_error_deg", "position_error_mm", "residual_px")}
    for v, cam in enumerate(ground_truth):
        rvec_true = cv2.Rodrigues(cam.R_cam_from_world)[0]
        seen_px, _ = cv2.projectPoints(X, rvec_true, cam.t_cam_from_world_m, cam.K, cam.distortion)
        K_centred = cam.K.copy()
        K_centred[:2, 2] = (cam.width_px / 2.0, cam.height_px / 2.0)
        _, rvec, tvec = cv2.solvePnP(X, seen_px, K_centred, cam.distortion, rvec_true.copy(),
                                     cam.t_cam_from_world_m.reshape(3, 1).copy(), useExtrinsicGuess=True,
                                     flags=cv2.SOLVEPNP_ITERATIVE)
        moved = Camera(K_centred, cv2.Rodrigues(rvec)[0], tvec.reshape(3), cam.width_px, cam.height_px, cam.distortion)
        again_px, _ = cv2.projectPoints(X, rvec, tvec, K_centred, cam.distortion)
        out["offset_px"][v] = float(np.linalg.norm(cam.K[:2, 2] - K_centred[:2, 2]))
        out["angle_error_deg"][v] = float(rotation_distance_deg(moved.R_cam_from_world[None], cam.R_cam_from_world[None])[0])
        out["position_error_mm"][v] = 1000.0 * float(np.linalg.norm(moved.center_world_m - cam.center_world_m))
        out["residual_px"][v] = float(np.linalg.norm(again_px - seen_px, axis=-1).mean())
    return out


def reprojection_errors_per_view(
    cameras: CameraRig, detections: pd.DataFrame, associations: pd.DataFrame, min_score: float = 0.0
) -> np.ndarray:
    """Mean reprojection error per view of the people triangulated (per frame) with ``cameras``.

    Args:
        cameras: V cameras.
        detections: canonical ``detections`` table.
        associations: canonical ``associations`` table (true ``person_id``; -1 rows are ignored).
        min_score: keypoints below this confidence are neither used nor scored.

    Returns:
        (V,) mean pixel error over the detected keypoints of associated detections (NaN for a view without any).
    """
    dense = detections_to_dense(detections)
    person = Associations.from_table(associations).person_of_detections(dense)
    keep = person >= 0
    V = len(cameras)
    keys, inverse = unique_rows(np.c_[dense.frame[keep], person[keep]])
    n, J = len(keys), dense.keypoints_px.shape[1]
    px = np.full((V, n, J, 2), np.nan)
    w = np.zeros((V, n, J))
    views = dense.view[keep]
    kp = dense.keypoints_px[keep]
    sc = np.where(dense.scores[keep] > min_score, dense.scores[keep], 0.0)
    px[views, inverse] = kp
    w[views, inverse] = sc
    X, _ = triangulate_dlt(cameras, px.reshape(V, n * J, 2), w.reshape(V, n * J))
    err = reprojection_errors_px(cameras, X, px.reshape(V, n * J, 2)).reshape(V, n, J)
    err = np.where(w > 0, err, np.nan)
    out = np.full(V, np.nan)
    for v in range(V):
        e = err[v][np.isfinite(err[v])]
        out[v] = e.mean() if len(e) else np.nan
    return out


def _rows(name: str, values: np.ndarray, unit: str) -> list[MetricRow]:
    rows = [MetricRow(name, float(np.nanmean(values)) if np.isfinite(values).any() else float("nan"), unit)]
    rows += [MetricRow(name, float(x), unit, view=v) for v, x in enumerate(values)]
    return rows


def camera_metrics(
    estimated: CameraRig,
    ground_truth: CameraRig,
    detections: pd.DataFrame | None = None,
    associations: pd.DataFrame | None = None,
) -> list[MetricRow]:
    """All camera metrics (see the module docstring) as metric rows.

    Args:
        estimated: the calibrated cameras.
        ground_truth: the true cameras, same views.
        detections, associations: when both are given, the reprojection metrics are added.

    Returns:
        Rows ``focal_error_pct``, ``position_error_mm``, ``angle_error_deg`` (and ``reprojection_error_px``,
        ``reprojection_error_gt_cameras_px``), each as the mean over views (``view`` None) and per view, and
        ``scale_error_pct`` (the rig's).
    """
    err = camera_errors(estimated, ground_truth)
    rows = (_rows("focal_error_pct", err["focal_error_pct"], "%") + _rows("position_error_mm", err["position_error_mm"], "mm")
            + _rows("angle_error_deg", err["angle_error_deg"], "deg")
            + [MetricRow("scale_error_pct", scale_error_pct(err["alignment"]), "%")])
    if detections is not None and associations is not None:
        rows += _rows("reprojection_error_px", reprojection_errors_per_view(estimated, detections, associations), "px")
        rows += _rows("reprojection_error_gt_cameras_px",
                      reprojection_errors_per_view(ground_truth, detections, associations), "px")
    return rows


def camera_metrics_table(
    dataset: str,
    sequence: str,
    estimated: CameraRig,
    ground_truth: CameraRig,
    detections: pd.DataFrame | None = None,
    associations: pd.DataFrame | None = None,
    method: str = METHOD,
    failed_checks: str = "",
) -> pd.DataFrame:
    """The canonical ``metrics`` table of :func:`camera_metrics` (method ``"init"`` by default); every row carries
    ``failed_checks``, the checks the estimated cameras failed (comma-separated; empty: none)."""
    rows = camera_metrics(estimated, ground_truth, detections, associations)
    return metrics_table(dataset, sequence, method, rows, failed_checks=failed_checks)
