"""Errors between predicted and true 3D joints (numpy): per joint, mean (MPJPE), after Procrustes (PA-MPJPE).

Inputs in metres, errors in millimetres. Library code (the lifter's held-out report) and the evaluation
protocols (``evaluation.metrics`` re-exports them) measure with the same functions.
"""

from __future__ import annotations

import numpy as np

from humancal.geometry.alignment import align_points

__all__ = ["joint_errors_mm", "mpjpe_mm", "pa_mpjpe_mm"]


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
