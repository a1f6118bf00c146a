"""The metric table of one sequence: every evaluated method, per dataset protocol."""

from __future__ import annotations

import pandas as pd

from evaluation.detection_quality import evaluate_grouping
from evaluation.protocols import evaluate_canonical_poses, evaluate_reprojection, evaluate_shelf_poses, metrics_table
from humancal.camera import CameraRig
from humancal.datasets.sequences import SequenceSpec

__all__ = ["baseline_metrics", "sequence_metric_table"]


def baseline_metrics(
    spec: SequenceSpec,
    poses: pd.DataFrame,
    detections: pd.DataFrame,
    associations: pd.DataFrame,
    cameras: CameraRig,
    gt_poses3d: pd.DataFrame,
    method: str = "gt_camera_triangulation",
) -> pd.DataFrame:
    """3D accuracy (the dataset's protocol) and 2D reprojection error of a canonical-23 reconstruction."""
    if spec.kind == "synthetic":
        rows = evaluate_canonical_poses(poses, gt_poses3d)
    elif spec.kind == "shelf":
        rows = evaluate_shelf_poses(poses, gt_poses3d)
    else:
        raise ValueError(f"sequence {spec.key}: no evaluation protocol for dataset kind {spec.kind!r}")
    rows += evaluate_reprojection(poses, detections, associations, cameras)
    return metrics_table(spec.dataset, spec.sequence, method, rows)


def sequence_metric_table(
    spec: SequenceSpec,
    *,
    gt_camera_triangulation: pd.DataFrame,
    detections: pd.DataFrame,
    associations: pd.DataFrame,
    cameras: CameraRig,
    gt_poses3d: pd.DataFrame,
) -> pd.DataFrame:
    """All rows of a sequence's metric table.

    Rows: the ``gt_camera_triangulation`` reference; for real datasets whose detections were grouped by
    humancal (Shelf), the grouping quality against the projected ground truth (method ``grouping``).
    """
    parts = [baseline_metrics(spec, gt_camera_triangulation, detections, associations, cameras, gt_poses3d)]
    if spec.kind == "shelf":
        grouping = evaluate_grouping(detections, gt_poses3d, cameras, dataset=spec.dataset).metrics
        parts.append(grouping.assign(sequence=spec.sequence))
    return pd.concat(parts, ignore_index=True)
