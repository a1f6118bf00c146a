"""The ``lifted_detections`` table: every 2D detection with the lifter's 3D pose, height and upright score.

One row per (frame, view, det_id, joint) for all 23 canonical joints of every detection: ``x_px, y_px, score``
are the 2D detection (NaN, NaN, 0 where the joint was not detected); ``x_crop_m, y_crop_m, z_crop_m`` the lifted
root-relative pose in the detection's crop frame (metres, OpenCV axes; the crop frame is the camera frame turned
to look at ``box_cx_px, box_cy_px``, see ``docs/lifter.md``; NaN where ``lifted`` is False); ``height_m`` and
``upright_score`` are per detection, repeated on its joint rows.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from humancal.keypoints import CANONICAL_JOINTS, JOINT_INDEX, NUM_JOINTS
from humancal.lifter.infer import LiftedPoses, Lifter, lift_detections
from humancal.tables.detections import DenseDetections, detections_to_dense

__all__ = ["lift_detections_table", "lifted_to_table", "lifted_from_table"]

_XYZ = ["x_crop_m", "y_crop_m", "z_crop_m"]


def lifted_to_table(sequence: str, detections: DenseDetections, lifted: LiftedPoses) -> pd.DataFrame:
    """The ``lifted_detections`` table of crop-frame poses (row-aligned with ``detections``).

    Raises:
        ValueError: the poses are not in crop frames or do not match the detections row for row.
    """
    if lifted.frame != "crop":
        raise ValueError("lifted_to_table stores crop-frame poses (lift without K)")
    D = len(detections)
    if len(lifted) != D:
        raise ValueError(f"{len(lifted)} lifted poses for {D} detections")
    per_det = lambda a: np.repeat(np.asarray(a), NUM_JOINTS)  # noqa: E731
    present = detections.scores > 0
    return pd.DataFrame(
        {
            "sequence": sequence,
            "frame": per_det(detections.frame).astype(np.int32),
            "view": per_det(detections.view).astype(np.int32),
            "det_id": per_det(detections.det_id).astype(np.int32),
            "joint": np.tile(np.array(CANONICAL_JOINTS, dtype=object), D),
            "x_px": np.where(present, detections.keypoints_px[..., 0], np.nan).reshape(-1),
            "y_px": np.where(present, detections.keypoints_px[..., 1], np.nan).reshape(-1),
            "score": detections.scores.reshape(-1).astype(np.float64),
            "x_crop_m": lifted.joints_cam_m[..., 0].reshape(-1),
            "y_crop_m": lifted.joints_cam_m[..., 1].reshape(-1),
            "z_crop_m": lifted.joints_cam_m[..., 2].reshape(-1),
            "box_cx_px": per_det(lifted.box_centre_px[:, 0]),
            "box_cy_px": per_det(lifted.box_centre_px[:, 1]),
            "height_m": per_det(lifted.height_m),
            "upright_score": per_det(lifted.upright_score),
            "lifted": per_det(lifted.valid),
        }
    )


def lift_detections_table(lifter: Lifter, detections: pd.DataFrame, sequence: str) -> pd.DataFrame:
    """Lift every detection of a canonical ``detections`` table; returns the ``lifted_detections`` table."""
    dense = detections_to_dense(detections)
    return lifted_to_table(sequence, dense, lift_detections(lifter, dense.keypoints_px, dense.scores))


def lifted_from_table(table: pd.DataFrame) -> tuple[DenseDetections, LiftedPoses]:
    """Dense detections and their crop-frame lifted poses from a ``lifted_detections`` table.

    Rows may come in any order.

    Raises:
        ValueError: a detection does not have each of the 23 canonical joints exactly once.
    """
    D = len(table) // NUM_JOINTS
    if len(table) % NUM_JOINTS:
        raise ValueError(f"lifted_detections: {len(table)} rows is not a multiple of {NUM_JOINTS} joints")
    joint_index = table["joint"].map(JOINT_INDEX)
    if joint_index.isna().any():
        raise ValueError(f"lifted_detections: non-canonical joint names {sorted(set(table['joint'][joint_index.isna()]))[:5]}")
    ordered = table.assign(_joint=joint_index).sort_values(["frame", "view", "det_id", "_joint"], kind="stable")
    if D and not (ordered["joint"].to_numpy().reshape(D, NUM_JOINTS) == np.array(CANONICAL_JOINTS)).all():
        raise ValueError("lifted_detections: every detection must list each of the 23 canonical joints once")
    first = ordered.iloc[::NUM_JOINTS]
    scores = ordered["score"].to_numpy(np.float64).reshape(D, NUM_JOINTS)
    keypoints = ordered[["x_px", "y_px"]].to_numpy(np.float64).reshape(D, NUM_JOINTS, 2)
    dense = DenseDetections(
        first["frame"].to_numpy(np.int64), first["view"].to_numpy(np.int64), first["det_id"].to_numpy(np.int64),
        keypoints, scores,
    )
    lifted = LiftedPoses(
        ordered[_XYZ].to_numpy(np.float64).reshape(D, NUM_JOINTS, 3),
        first["height_m"].to_numpy(np.float64),
        first["upright_score"].to_numpy(np.float64),
        first["lifted"].to_numpy(bool),
        first[["box_cx_px", "box_cy_px"]].to_numpy(np.float64),
        "crop",
    )
    return dense, lifted
