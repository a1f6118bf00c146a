"""Dense array views of the long ``detections`` table.

The table has one row per present joint; methods work on dense arrays with one row per detection
and a separate validity mask (confidence is never packed into a coordinate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.keypoints import CANONICAL_JOINTS, JOINT_INDEX, NUM_JOINTS

__all__ = ["DenseDetections", "detections_to_dense"]


@dataclass(frozen=True)
class DenseDetections:
    """Detections as arrays, one row per (frame, view, det_id).

    Attributes:
        frame, view, det_id: (D,) int identifiers of each detection.
        keypoints_px: (D, 23, 2) canonical keypoints in pixels (NaN where absent).
        scores: (D, 23) confidences in [0, 1] (0 where absent).
    """

    frame: np.ndarray
    view: np.ndarray
    det_id: np.ndarray
    keypoints_px: np.ndarray
    scores: np.ndarray

    def __len__(self) -> int:
        return len(self.frame)

    @property
    def valid(self) -> np.ndarray:
        """(D, 23) True where the joint was detected."""
        return self.scores > 0


def detections_to_dense(detections: pd.DataFrame) -> DenseDetections:
    """Pivot the canonical detections table to :class:`DenseDetections` (sorted by frame, view, det_id).

    Raises:
        ValueError: a joint name is not canonical, or a (frame, view, det_id, joint) appears twice.
    """
    unknown = sorted(set(detections["joint"].unique()) - set(CANONICAL_JOINTS))
    if unknown:
        raise ValueError(f"detections: column 'joint' has non-canonical names {unknown[:5]}")
    keys = detections[["frame", "view", "det_id"]].to_numpy(dtype=np.int64)
    if len(keys) == 0:
        z = np.zeros(0, dtype=np.int64)
        return DenseDetections(z, z, z, np.zeros((0, NUM_JOINTS, 2)), np.zeros((0, NUM_JOINTS)))
    uniq, row = np.unique(keys, axis=0, return_inverse=True)
    row = row.reshape(-1)
    col = detections["joint"].map(JOINT_INDEX).to_numpy()
    flat = row * NUM_JOINTS + col
    if len(np.unique(flat)) != len(flat):
        raise ValueError("detections: a (frame, view, det_id, joint) appears more than once")
    kp = np.full((len(uniq), NUM_JOINTS, 2), np.nan)
    sc = np.zeros((len(uniq), NUM_JOINTS))
    kp[row, col, 0] = detections["x_px"].to_numpy()
    kp[row, col, 1] = detections["y_px"].to_numpy()
    sc[row, col] = detections["score"].to_numpy()
    return DenseDetections(uniq[:, 0], uniq[:, 1], uniq[:, 2], kp, sc)
