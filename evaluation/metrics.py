"""Metric functions on arrays (pure numpy; no tables, no I/O).

The joint errors (``joint_errors_mm``, ``mpjpe_mm``, ``pa_mpjpe_mm``) live in :mod:`humancal.geometry.pose_errors`,
which the library uses too; they are re-exported here with the evaluation-only metrics.

Units: inputs in metres, 3D errors returned in millimetres, 2D errors in pixels.
"""

from __future__ import annotations

import numpy as np

from humancal.geometry.alignment import align_points
from humancal.geometry.pose_errors import joint_errors_mm, mpjpe_mm, pa_mpjpe_mm

__all__ = ["joint_errors_mm", "mpjpe_mm", "pa_mpjpe_mm", "pcp_correct", "similarity_align"]


def similarity_align(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Align ``source`` to ``target`` with the least-squares similarity (scale, rotation, translation).

    Args:
        source, target: (J, 3) corresponding points (all finite, J >= 3).

    Returns:
        (J, 3) aligned source points.
    """
    return align_points(source, target)


def pcp_correct(pred_m: np.ndarray, gt_m: np.ndarray, limbs: list[tuple[int, int]], alpha: float = 0.5) -> np.ndarray:
    """Percentage-of-correct-parts test per limb (the Shelf/Campus rule).

    A limb (a, b) is correct when the mean of its two end-point errors is below ``alpha`` times the
    ground-truth limb length: (|a - a_gt| + |b - b_gt|) / 2 < alpha |a_gt - b_gt|. A missing (NaN)
    prediction is incorrect.

    Args:
        pred_m, gt_m: (N, J, 3) joints in metres.
        limbs: L pairs of joint indices.
        alpha: fraction of the limb length (0.5 in the standard protocol).

    Returns:
        (N, L) boolean array.
    """
    a, b = np.array(limbs).T
    err = np.linalg.norm(pred_m - gt_m, axis=-1)
    length = np.linalg.norm(gt_m[:, a] - gt_m[:, b], axis=-1)
    ok = (err[:, a] + err[:, b]) / 2.0 < alpha * length
    return np.where(np.isfinite(err[:, a] + err[:, b]), ok, False)
