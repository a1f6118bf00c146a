"""Metric functions on arrays (pure numpy; no tables, no I/O).

Units: inputs in metres, 3D errors returned in millimetres, 2D errors in pixels.
"""

from __future__ import annotations

import numpy as np

from humancal.geometry.alignment import align_points

__all__ = ["joint_errors_mm", "mpjpe_mm", "pa_mpjpe_mm", "pcp_correct", "similarity_align"]


def joint_errors_mm(pred_m: np.ndarray, gt_m: np.ndarray) -> np.ndarray:
    """Per-joint Euclidean error.

    Args:
        pred_m, gt_m: (..., J, 3) joints in metres.

    Returns:
        (..., J) errors in millimetres (NaN where either side is NaN).
    """
    return 1000.0 * np.linalg.norm(np.asarray(pred_m) - np.asarray(gt_m), axis=-1)


def mpjpe_mm(pred_m: np.ndarray, gt_m: np.ndarray, valid: np.ndarray | None = None) -> float:
    """Mean per-joint position error over valid joints, millimetres (NaN when nothing is valid).

    Args:
        pred_m, gt_m: (N, J, 3) joints in metres.
        valid: (N, J) mask; defaults to joints finite on both sides.
    """
    err = joint_errors_mm(pred_m, gt_m)
    mask = np.isfinite(err) if valid is None else (np.asarray(valid, bool) & np.isfinite(err))
    return float(err[mask].mean()) if mask.any() else float("nan")


def similarity_align(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Align ``source`` to ``target`` with the least-squares similarity (scale, rotation, translation).

    Args:
        source, target: (J, 3) corresponding points (all finite, J >= 3).

    Returns:
        (J, 3) aligned source points.
    """
    return align_points(source, target)


def pa_mpjpe_mm(pred_m: np.ndarray, gt_m: np.ndarray, valid: np.ndarray | None = None) -> float:
    """MPJPE after per-pose similarity (Procrustes) alignment of the prediction to the ground truth.

    Args:
        pred_m, gt_m: (N, J, 3) joints in metres.
        valid: (N, J) mask; poses with fewer than 3 valid joints are skipped.

    Returns:
        millimetres (NaN when no pose qualifies).
    """
    pred_m, gt_m = np.asarray(pred_m, dtype=np.float64), np.asarray(gt_m, dtype=np.float64)
    finite = np.isfinite(pred_m).all(-1) & np.isfinite(gt_m).all(-1)
    mask = finite if valid is None else (finite & np.asarray(valid, bool))
    enough = mask.sum(-1) >= 3
    if not enough.any():
        return float("nan")
    aligned = align_points(pred_m[enough], gt_m[enough], mask[enough].astype(np.float64))
    return float(joint_errors_mm(aligned, gt_m[enough])[mask[enough]].mean())


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
