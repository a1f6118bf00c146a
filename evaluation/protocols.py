"""Evaluation protocols: which joints, which limbs, how predictions meet the ground truth.

The canonical protocol scores canonical-23 predictions against canonical-23 ground truth (the
synthetic datasets). PCP uses the ten Shelf/Campus-style parts, with the two joints the canonical
set lacks derived the same way on both sides: neck = shoulder midpoint, pelvis = hip midpoint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from evaluation.metrics import mpjpe_mm, pa_mpjpe_mm, pcp_correct
from humancal.camera import CameraRig
from humancal.formats import SKELETONS, from_canonical
from humancal.geometry.alignment import fit_similarity
from humancal.geometry.triangulation import reprojection_errors_px
from humancal.keypoints import CANONICAL_JOINTS, JOINT_INDEX
from humancal.tables.associations import Associations
from humancal.tables.detections import detections_to_dense
from humancal.tables.poses import poses_to_dense
from humancal.tables.schemas import validate_table

__all__ = ["MetricRow", "metrics_table", "evaluate_canonical_poses", "evaluate_reprojection", "evaluate_shelf_poses"]

# Joints of the canonical PCP skeleton: the 23 canonical ones plus two derived (neck, pelvis).
_NECK, _PELVIS = len(CANONICAL_JOINTS), len(CANONICAL_JOINTS) + 1
_J = JOINT_INDEX
CANONICAL_PCP_PARTS: dict[str, tuple[int, int]] = {
    "left_upper_arm": (_J["left_shoulder"], _J["left_elbow"]),
    "right_upper_arm": (_J["right_shoulder"], _J["right_elbow"]),
    "left_lower_arm": (_J["left_elbow"], _J["left_wrist"]),
    "right_lower_arm": (_J["right_elbow"], _J["right_wrist"]),
    "left_upper_leg": (_J["left_hip"], _J["left_knee"]),
    "right_upper_leg": (_J["right_hip"], _J["right_knee"]),
    "left_lower_leg": (_J["left_knee"], _J["left_ankle"]),
    "right_lower_leg": (_J["right_knee"], _J["right_ankle"]),
    "head": (_NECK, _J["nose"]),
    "torso": (_NECK, _PELVIS),
}


@dataclass(frozen=True)
class MetricRow:
    """One figure of a metric table.

    Attributes:
        metric: the metric's name (units in the name where it has one, e.g. ``mpjpe_mm``).
        value: the figure.
        unit: ``mm``, ``px``, ``%``, ``deg``, ``count``, ...
        view: the view the figure is about; None for a figure that is not per view.
    """

    metric: str
    value: float
    unit: str
    view: int | None = None


def metrics_table(
    dataset: str, sequence: str, method: str, rows: list[MetricRow], failed_checks: str | None = None
) -> pd.DataFrame:
    """The canonical ``metrics`` table for one method on one sequence (``view`` null where a row has none).

    Args:
        failed_checks: for figures computed from estimated cameras, the checks those cameras failed
            (comma-separated; empty: none); None for figures that are not.
    """
    df = pd.DataFrame(
        {
            "dataset": dataset,
            "sequence": sequence,
            "method": method,
            "metric": [r.metric for r in rows],
            "view": pd.array([r.view for r in rows], dtype="Int32"),
            "value": [float(r.value) for r in rows],
            "unit": [r.unit for r in rows],
            "failed_checks": pd.Series([failed_checks] * len(rows), dtype=object),
        },
        columns=["dataset", "sequence", "method", "metric", "view", "value", "unit", "failed_checks"],
    )
    return validate_table(df, "metrics")


def _with_neck_pelvis(X: np.ndarray) -> np.ndarray:
    neck = 0.5 * (X[:, _J["left_shoulder"]] + X[:, _J["right_shoulder"]])
    pelvis = 0.5 * (X[:, _J["left_hip"]] + X[:, _J["right_hip"]])
    return np.concatenate([X, neck[:, None], pelvis[:, None]], axis=1)


def _sequence_aligned(X_pred: np.ndarray, X_gt: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``X_pred`` moved by the one similarity (scale, rotation, translation) that best maps all its ``mask``ed
    joints onto the ground truth's over the whole sequence (7 parameters for thousands of joints: the frame of a
    self-calibrated world, not a per-pose fit)."""
    if mask.sum() < 3:
        return X_pred
    similarity = fit_similarity(X_pred[mask], X_gt[mask])
    return similarity.apply(X_pred.reshape(-1, 3)).reshape(X_pred.shape)


def evaluate_canonical_poses(pred: pd.DataFrame, gt: pd.DataFrame, sequence_aligned: bool = False) -> list[MetricRow]:
    """Score canonical-23 ``poses3d`` predictions against canonical-23 ground truth.

    Predictions meet the ground truth by (frame, person_id). A ground-truth pose without a
    prediction counts as wrong for PCP and lowers ``coverage``; MPJPE and PA-MPJPE average over
    joints valid on both sides. ``sequence_aligned``: the predictions are first moved by the one similarity
    that best maps them onto the ground truth over the whole sequence.

    Returns:
        rows ``mpjpe_mm``, ``pa_mpjpe_mm``, ``pcp_avg`` (percent, over ground-truth poses and the
        ten parts), ``pcp_<part>`` per part, ``coverage`` (percent of ground-truth joints predicted).
    """
    g = poses_to_dense(gt, CANONICAL_JOINTS)
    p = poses_to_dense(pred, CANONICAL_JOINTS)
    pred_index = {(f, i): n for n, (f, i) in enumerate(zip(p.frame, p.person_id))}
    rows = np.array([pred_index.get((f, i), -1) for f, i in zip(g.frame, g.person_id)], dtype=np.int64)
    X_pred = np.full_like(g.joints_world_m, np.nan)
    has = rows >= 0
    X_pred[has] = p.joints_world_m[rows[has]]
    both = g.valid & np.isfinite(X_pred).all(-1)
    if sequence_aligned:
        X_pred = _sequence_aligned(X_pred, g.joints_world_m, both)

    parts = list(CANONICAL_PCP_PARTS)
    correct = pcp_correct(_with_neck_pelvis(X_pred), _with_neck_pelvis(g.joints_world_m), list(CANONICAL_PCP_PARTS.values()))
    out = [
        MetricRow("mpjpe_mm", mpjpe_mm(X_pred, g.joints_world_m, both), "mm"),
        MetricRow("pa_mpjpe_mm", pa_mpjpe_mm(X_pred, g.joints_world_m, both), "mm"),
        MetricRow("pcp_avg", 100.0 * correct.mean() if correct.size else float("nan"), "%"),
    ]
    out += [MetricRow(f"pcp_{name}", 100.0 * correct[:, k].mean() if len(correct) else float("nan"), "%") for k, name in enumerate(parts)]
    out.append(MetricRow("coverage", 100.0 * both.sum() / max(g.valid.sum(), 1), "%"))
    return out


def evaluate_reprojection(
    poses: pd.DataFrame, detections: pd.DataFrame, associations: pd.DataFrame, cameras: CameraRig
) -> list[MetricRow]:
    """2D reprojection error of canonical 3D poses against the detections assigned to each person.

    Returns:
        ``reprojection_error_px`` (mean over all observed joints), ``reprojection_error_median_px``,
        and ``reprojection_error_px/<joint>`` per canonical joint.
    """
    dense = detections_to_dense(detections)
    p = poses_to_dense(poses, CANONICAL_JOINTS)
    person = Associations.from_table(associations).person_of_detections(dense)
    pose_row = {(f, i): n for n, (f, i) in enumerate(zip(p.frame, p.person_id))}
    match = np.array([pose_row.get((f, i), -1) for f, i in zip(dense.frame, person)], dtype=np.int64)
    errors = np.full(dense.scores.shape, np.nan)
    for v, cam in enumerate(cameras):
        sel = (dense.view == v) & (match >= 0) & (person >= 0)
        if sel.any():
            X = p.joints_world_m[match[sel]]  # (n, J, 3)
            e = reprojection_errors_px([cam], X.reshape(-1, 3), dense.keypoints_px[sel].reshape(1, -1, 2))
            errors[sel] = e.reshape(X.shape[:2])
    errors[~dense.valid] = np.nan
    finite = np.isfinite(errors)
    out = [
        MetricRow("reprojection_error_px", float(errors[finite].mean()) if finite.any() else float("nan"), "px"),
        MetricRow("reprojection_error_median_px", float(np.median(errors[finite])) if finite.any() else float("nan"), "px"),
    ]
    for j, name in enumerate(CANONICAL_JOINTS):
        col = errors[:, j][np.isfinite(errors[:, j])]
        out.append(MetricRow(f"reprojection_error_px/{name}", float(col.mean()) if len(col) else float("nan"), "px"))
    return out


# The Shelf/Campus protocol: the first 14 SHELF15 joints, the ten standard parts (pairs of those joints),
# actors 1-3 = ground-truth ids 0, 1, 2, head joints of the prediction derived by the mvpose rule
# (humancal.formats.skeletons), every annotated actor-frame scored (a missing prediction is wrong).
SHELF_PCP_PARTS: dict[str, tuple[int, int]] = {
    "left_upper_arm": (9, 10),
    "right_upper_arm": (8, 7),
    "left_lower_arm": (10, 11),
    "right_lower_arm": (7, 6),
    "left_upper_leg": (3, 4),
    "right_upper_leg": (2, 1),
    "left_lower_leg": (4, 5),
    "right_lower_leg": (1, 0),
    "head": (12, 13),
    "torso": (12, 14),
}
SHELF_ACTORS = (0, 1, 2)


def evaluate_shelf_poses(pred: pd.DataFrame, gt: pd.DataFrame, sequence_aligned: bool = False) -> list[MetricRow]:
    """Score canonical-23 predictions (person ids = ground-truth ids) against SHELF15 ground truth
    (``sequence_aligned``: first moved by the one similarity that best maps their 14 evaluated joints onto the
    ground truth's over the whole sequence).

    Returns:
        ``pcp_actor1``..``pcp_actor3`` and ``pcp_avg`` (percent; the average of the three actors),
        ``pcp_<part>`` over the three actors (``pcp_head`` is the weakest part for every method, so it
        is worth reading on its own), ``mpjpe_mm`` over the 14 evaluated joints.
    """
    shelf15 = SKELETONS["shelf15"].joints
    g = poses_to_dense(gt, shelf15)
    p = poses_to_dense(pred, CANONICAL_JOINTS)
    scores = np.where(p.valid, 1.0, 0.0)
    pred15, pred_scores = from_canonical(np.nan_to_num(p.joints_world_m), scores, "shelf15")
    pred15 = np.where(pred_scores[..., None] > 0, pred15, np.nan)
    index = {(f, i): n for n, (f, i) in enumerate(zip(p.frame, p.person_id))}
    rows = np.array([index.get((f, i), -1) for f, i in zip(g.frame, g.person_id)], dtype=np.int64)
    X = np.full_like(g.joints_world_m, np.nan)
    X[rows >= 0] = pred15[rows[rows >= 0]]
    if sequence_aligned:
        evaluated = g.valid[:, :14] & np.isin(g.person_id, SHELF_ACTORS)[:, None] & np.isfinite(X[:, :14]).all(-1)
        X = _sequence_aligned(X, g.joints_world_m, np.pad(evaluated, ((0, 0), (0, X.shape[1] - 14))))
    correct = pcp_correct(X, g.joints_world_m, list(SHELF_PCP_PARTS.values()))  # (N, 10)
    out, per_actor = [], []
    for k, actor in enumerate(SHELF_ACTORS):
        sel = g.person_id == actor
        value = 100.0 * correct[sel].mean() if sel.any() else float("nan")
        per_actor.append(value)
        out.append(MetricRow(f"pcp_actor{k + 1}", value, "%"))
    out.append(MetricRow("pcp_avg", float(np.nanmean(per_actor)), "%"))
    actors = np.isin(g.person_id, SHELF_ACTORS)
    for j, name in enumerate(SHELF_PCP_PARTS):
        out.append(MetricRow(f"pcp_{name}", 100.0 * correct[actors, j].mean() if actors.any() else float("nan"), "%"))
    evaluated = g.valid[:, :14] & actors[:, None]
    out.append(MetricRow("mpjpe_mm", mpjpe_mm(X[:, :14], g.joints_world_m[:, :14], evaluated), "mm"))
    return out
