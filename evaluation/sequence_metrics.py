"""Metric tables of one sequence, per dataset protocol."""

from __future__ import annotations

import pandas as pd

from evaluation.protocols import evaluate_canonical_poses, evaluate_reprojection, evaluate_shelf_poses, metrics_table
from humancal.camera import Camera
from humancal.sequences import SequenceSpec

__all__ = ["baseline_metrics"]


def baseline_metrics(
    spec: SequenceSpec,
    poses: pd.DataFrame,
    detections: pd.DataFrame,
    associations: pd.DataFrame,
    cameras: list[Camera],
    gt_poses3d: pd.DataFrame,
    method: str = "gt_camera_triangulation",
) -> pd.DataFrame:
    """3D accuracy (dataset protocol) and 2D reprojection error of a canonical-23 reconstruction."""
    if spec.kind == "synthetic":
        rows = evaluate_canonical_poses(poses, gt_poses3d)
    elif spec.kind == "shelf":
        rows = evaluate_shelf_poses(poses, gt_poses3d)
    else:
        raise ValueError(f"sequence {spec.key}: no evaluation protocol for dataset kind {spec.kind!r}")
    rows += evaluate_reprojection(poses, detections, associations, cameras)
    return metrics_table(spec.dataset, spec.sequence, method, rows)
