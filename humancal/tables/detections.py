"""Dense array views of the long ``detections`` table.

The table has one row per present joint; methods work on dense arrays with one row per detection
and a separate validity mask (confidence is never packed into a coordinate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.keypoints import CANONICAL_JOINTS, NUM_JOINTS
from humancal.tables.pivot import has_repeats, name_codes, unique_rows

__all__ = ["DenseDetections", "dense_to_detections", "detections_to_dense"]


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
    col = name_codes(detections["joint"], CANONICAL_JOINTS)
    if (col < 0).any():
        unknown = sorted(map(str, detections["joint"][col < 0].unique()))
        raise ValueError(f"detections: column 'joint' has non-canonical names {unknown[:5]}")
    keys = detections[["frame", "view", "det_id"]].to_numpy(dtype=np.int64)
    if len(keys) == 0:
        z = np.zeros(0, dtype=np.int64)
        return DenseDetections(z, z, z, np.zeros((0, NUM_JOINTS, 2)), np.zeros((0, NUM_JOINTS)))
    uniq, row = unique_rows(keys)
    flat = row * NUM_JOINTS + col
    if has_repeats(flat, len(uniq) * NUM_JOINTS):
        raise ValueError("detections: a (frame, view, det_id, joint) appears more than once")
    kp = np.full((len(uniq), NUM_JOINTS, 2), np.nan)
    sc = np.zeros((len(uniq), NUM_JOINTS))
    kp[row, col, 0] = detections["x_px"].to_numpy()
    kp[row, col, 1] = detections["y_px"].to_numpy()
    sc[row, col] = detections["score"].to_numpy()
    return DenseDetections(uniq[:, 0], uniq[:, 1], uniq[:, 2], kp, sc)


def dense_to_detections(dense: DenseDetections, sequence: str) -> pd.DataFrame:
    """The canonical ``detections`` table of :class:`DenseDetections` (the inverse of :func:`detections_to_dense`):
    one row per joint with a score above 0, sorted by frame, view, det_id and canonical joint order.

    Args:
        dense: the detections.
        sequence: the ``sequence`` column's value.
    """
    rows, joints = np.nonzero(dense.valid & np.isfinite(dense.keypoints_px).all(axis=-1))
    order = np.lexsort((joints, dense.det_id[rows], dense.view[rows], dense.frame[rows]))
    rows, joints = rows[order], joints[order]
    return pd.DataFrame({
        "sequence": np.full(len(rows), sequence, dtype=object),
        "frame": dense.frame[rows].astype(np.int32),
        "view": dense.view[rows].astype(np.int32),
        "det_id": dense.det_id[rows].astype(np.int32),
        "joint": np.asarray(CANONICAL_JOINTS, dtype=object)[joints],
        "x_px": dense.keypoints_px[rows, joints, 0],
        "y_px": dense.keypoints_px[rows, joints, 1],
        "score": dense.scores[rows, joints],
    })
