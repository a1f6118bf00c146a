"""Quality of grouped 2D detections against projected ground-truth people (any dataset with 3D ground truth).

Protocol (``docs/shelf.md``):

* The ground-truth joints evaluated are those whose names the detections table and the ground-truth table share
  (for Shelf: shoulders, elbows, wrists, hips, knees, ankles), or the ``joints`` given.
* Each ground-truth person is projected into each view with the ground-truth camera. A projected joint is
  *visible* when it lies in front of the camera and inside the image, ``0 <= x < width`` and ``0 <= y < height``.
  A ground-truth **person-view counts** when at least ``min_visible_fraction`` (default half) of its evaluated
  joints are visible.
* A detection and a projected person are *close* when they share at least ``min_common_joints`` common joints
  (visible in the projection and detected) and the mean pixel distance over those joints is below
  ``threshold_fraction`` (default 5 %) of the image diagonal.
* Per view and frame, detections are matched one-to-one to the counted person-views by
  ``scipy.optimize.linear_sum_assignment`` on the mean distance, among close pairs only. The matching itself is
  the library's (:func:`humancal.datasets.gt_matching.match_ground_truth`: Shelf's reader labels detections
  with it); this module scores it.

Metrics (per view, the row's ``view``, and overall, ``view`` null):

* ``detection_recall`` = matched person-views / counted person-views.
* ``detection_fragment_rate`` = unmatched detections close to some ground-truth person (counted or not) /
  matched detections.
* ``median_joint_error_px`` = median pixel distance over the common joints of the matched pairs.
* ``gt_person_views``, ``matched_detections``, ``fragment_detections``, ``detections`` (counts).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.camera import CameraRig
from humancal.datasets.gt_matching import match_ground_truth
from humancal.tables.schemas import validate_table

__all__ = ["GroupingEvaluation", "evaluate_grouping", "detection_quality_metrics"]


@dataclass(frozen=True)
class GroupingEvaluation:
    """Per-item results of :func:`evaluate_grouping` and the metrics table built from them.

    Attributes:
        person_views, detections, joint_errors_px: the matching of the detections to the projected ground truth,
            as in :class:`humancal.datasets.gt_matching.GroundTruthMatch`.
        metrics: canonical ``metrics`` table.
    """

    person_views: pd.DataFrame
    detections: pd.DataFrame
    joint_errors_px: pd.DataFrame
    metrics: pd.DataFrame


def evaluate_grouping(
    detections: pd.DataFrame,
    gt_poses: pd.DataFrame,
    cameras: CameraRig,
    *,
    dataset: str,
    method: str = "grouping",
    joints: Sequence[str] | None = None,
    threshold_fraction: float = 0.05,
    min_visible_fraction: float = 0.5,
    min_common_joints: int = 1,
) -> GroupingEvaluation:
    """Match grouped 2D detections to projected ground-truth people and score the grouping.

    Args:
        detections: canonical ``detections`` table (pixels); rows with score 0 count as undetected.
        gt_poses: canonical ``poses3d`` table (world, metres); rows with ``valid`` False are ignored.
        cameras: ground-truth cameras, indexed by ``view``.
        dataset: dataset name for the metrics table.
        method: method name for the metrics table.
        joints: joint names to evaluate; default: the names both tables use, in ground-truth order.
        threshold_fraction: closeness threshold as a fraction of the image diagonal.
        min_visible_fraction: fraction of evaluated joints that must be visible for a person-view to count.
        min_common_joints: fewest common joints for a detection to be close to a person.

    Returns:
        The per-item results and the metrics table (see module docstring).

    Raises:
        ValueError: no shared joint names, views without a camera, or bad parameters.
        humancal.tables.schemas.TableError: a table does not match its schema.
    """
    match = match_ground_truth(
        detections,
        gt_poses,
        cameras,
        joints=joints,
        threshold_fraction=threshold_fraction,
        min_visible_fraction=min_visible_fraction,
        min_common_joints=min_common_joints,
    )
    metrics = detection_quality_metrics(
        match.person_views, match.detections, match.joint_errors_px, dataset=dataset, method=method
    )
    return GroupingEvaluation(match.person_views, match.detections, match.joint_errors_px, metrics)


def detection_quality_metrics(
    person_views: pd.DataFrame,
    detections: pd.DataFrame,
    joint_errors_px: pd.DataFrame,
    *,
    dataset: str,
    method: str = "grouping",
) -> pd.DataFrame:
    """The canonical ``metrics`` table from the per-item tables of :class:`GroupingEvaluation`.

    Rows per sequence: each metric overall (``view`` null) and per view. Recall and fragment rate are NaN
    where their denominator is zero, the median error where nothing matched.
    """
    rows = []
    sequences = sorted(set(person_views["sequence"]) | set(detections["sequence"]))
    for seq in sequences:
        pv = person_views[person_views["sequence"] == seq]
        dt = detections[detections["sequence"] == seq]
        er = joint_errors_px[joint_errors_px["sequence"] == seq]
        views = sorted(set(pv["view"]) | set(dt["view"]))
        for sel in [None, *views]:
            p = pv if sel is None else pv[pv["view"] == sel]
            d = dt if sel is None else dt[dt["view"] == sel]
            e = er if sel is None else er[er["view"] == sel]
            counted = int(p["counted"].sum())
            matched = int((p["det_id"] >= 0).sum())
            fragments = int(d["fragment"].sum())
            figures = [
                ("detection_recall", matched / counted if counted else np.nan, "fraction"),
                ("detection_fragment_rate", fragments / matched if matched else np.nan, "fraction"),
                ("median_joint_error_px", float(np.median(e["error_px"])) if len(e) else np.nan, "px"),
                ("gt_person_views", counted, "count"),
                ("matched_detections", matched, "count"),
                ("fragment_detections", fragments, "count"),
                ("detections", len(d), "count"),
            ]
            rows.extend((dataset, seq, method, name, sel, float(value), unit) for name, value, unit in figures)
    table = pd.DataFrame(rows, columns=["dataset", "sequence", "method", "metric", "view", "value", "unit"])
    table["view"] = table["view"].astype("Int32")
    table["failed_checks"] = None  # figures of the detections, not of estimated cameras
    return validate_table(table, "metrics", source="detection_quality_metrics")
