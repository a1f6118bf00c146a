"""Accuracy of a lifter on synthesised samples with known 3D truth (``humancal.geometry.pose_errors``).

All pose errors are root-relative (hip midpoint at the origin on both sides):

* ``mpjpe_mm``: mean per-joint position error. The same in the crop frame and, given the intrinsics, in the
  camera frame (both sides turn by the same rotation);
* ``pa_mpjpe_mm``: after a per-pose similarity (Procrustes) alignment;
* ``mpjpe_no_intrinsics_mm``: the crop-frame prediction taken as a camera-frame pose (what a consumer gets
  when it ignores the crop frame): adds the angle between the optical axis and the ray to the person;
* ``height_mae_mm``, ``height_bias_mm``: :func:`height_from_pose_m` of the prediction against the clip's
  reference height (:func:`humancal.lifter.data.clip_heights_m` of its true keypoints).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from humancal.geometry.pose_errors import mpjpe_mm, pa_mpjpe_mm
from humancal.lifter.data import LifterSamples, synthesize_samples
from humancal.lifter.infer import Lifter, lift_detections
from humancal.lifter.pose_cues import height_from_pose_m

__all__ = [
    "evaluate_predictions",
    "evaluate_lifter",
    "HELD_OUT_CMU_SUBJECTS",
    "split_held_out",
    "held_out_report",
]


def evaluate_predictions(pred_crop_m: np.ndarray, samples: LifterSamples) -> dict[str, float]:
    """Metrics of crop-frame predictions against the samples' truth (see the module docstring).

    Args:
        pred_crop_m: (N, 23, 3) predicted root-relative joints in the crop frame, metres.
        samples: the N samples they were predicted from.

    Returns:
        ``{"num_samples", "mpjpe_mm", "pa_mpjpe_mm", "mpjpe_no_intrinsics_mm", "height_mae_mm",
        "height_bias_mm"}``.

    Raises:
        ValueError: the prediction does not have the samples' shape.
    """
    pred = np.asarray(pred_crop_m, dtype=np.float64)
    if pred.shape != samples.targets_m.shape:
        raise ValueError(f"pred_crop_m must have shape {samples.targets_m.shape}, got {pred.shape}")
    target = samples.targets_m.astype(np.float64)
    height_error_m = height_from_pose_m(pred) - samples.height_m
    return {
        "num_samples": float(len(samples)),
        "mpjpe_mm": mpjpe_mm(pred, target),
        "pa_mpjpe_mm": pa_mpjpe_mm(pred, target),
        "mpjpe_no_intrinsics_mm": mpjpe_mm(pred, samples.targets_cam_m),
        "height_mae_mm": float(1000.0 * np.nanmean(np.abs(height_error_m))),
        "height_bias_mm": float(1000.0 * np.nanmean(height_error_m)),
    }


def evaluate_lifter(lifter: Lifter, samples: LifterSamples) -> dict[str, float]:
    """Lift the samples' raw detections with :func:`lift_detections` and score them.

    The camera-frame output (intrinsics given) is turned back into the crop frame by the samples' known
    rotations, so this exercises the whole inference path.

    Returns:
        The metrics of :func:`evaluate_predictions`.
    """
    lifted = lift_detections(lifter, samples.keypoints_px, samples.scores, K=samples.K)
    if not lifted.valid.all():
        raise ValueError(
            f"{int((~lifted.valid).sum())} samples were not liftable; samples must come from synthesize_samples"
        )
    pred_crop = lifted.joints_cam_m @ samples.R_crop_from_cam.transpose(0, 2, 1)
    return evaluate_predictions(pred_crop, samples)


HELD_OUT_CMU_SUBJECTS: tuple[str, ...] = ("02", "14")
"""CMU subjects held out from lifter training: 02 (walk, run, jump, punch, swordplay) and 14 (everyday
actions); both kinds of motion also occur among the training subjects (07-09, 13)."""

HELD_OUT_EVAL_SAMPLES = 20_000
"""Fresh samples of the held-out report (another seed than training's validation set)."""

HELD_OUT_EVAL_SEED = 12345


def split_held_out(
    clips: Sequence[tuple[str, np.ndarray]], held_out: Sequence[str] = HELD_OUT_CMU_SUBJECTS
) -> tuple[list[tuple[str, np.ndarray]], list[tuple[str, np.ndarray]]]:
    """Split ``(subject, keypoints_world_m)`` clips into training and held-out clips by whole subjects.

    Raises:
        ValueError: one of the two parts is empty (names the subjects found).
    """
    held = set(held_out)
    train = [c for c in clips if c[0] not in held]
    val = [c for c in clips if c[0] in held]
    if not train or not val:
        found = sorted({c[0] for c in clips})
        raise ValueError(f"held-out subjects {sorted(held)} leave no training or no held-out clips (subjects: {found})")
    return train, val


def held_out_report(
    lifter: Lifter,
    val_clips: Sequence[tuple[str, np.ndarray]],
    num_samples: int = HELD_OUT_EVAL_SAMPLES,
    seed: int = HELD_OUT_EVAL_SEED,
) -> pd.DataFrame:
    """Metrics on fresh samples of held-out clips, overall and by how much of the body each detection shows.

    Returns:
        One row per group (``all``, ``>= 20 of 23 joints``, ``12-19 joints``, ``< 12 joints``,
        ``left-right flipped``), index ``detections``: ``share_pct`` and the metrics of
        :func:`evaluate_predictions` (``num_samples`` included).
    """
    samples = synthesize_samples(val_clips, num_samples, lifter.config.samples, np.random.default_rng(seed))
    joints = (samples.scores > 0).sum(axis=1)
    groups = {
        "all": np.ones(len(samples), bool),
        ">= 20 of 23 joints": joints >= 20,
        "12-19 joints": (joints >= 12) & (joints < 20),
        "< 12 joints": joints < 12,
        "left-right flipped": samples.flipped,
    }
    rows = [
        {"detections": name, "share_pct": 100.0 * mask.mean(), **evaluate_lifter(lifter, samples.subset(mask))}
        for name, mask in groups.items()
        if mask.any()
    ]
    return pd.DataFrame(rows).set_index("detections")
