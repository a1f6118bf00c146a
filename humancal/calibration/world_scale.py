"""The world's metric scale, from the people's limbs and the size of a reference adult.

Detections fix the cameras and the people up to one factor: the same images come from a world twice as large. The
calibration takes that factor from the people. Its bundle adjustment compares the triangulated people with their
lifted poses, which carry the size the lifter learned, and the lifter hardly tells people apart by size: on the
demo scene it lifted people of 1.56, 1.64, 1.83 and 1.92 m at 1.63-1.69 m, a few centimetres under its training
subjects' height (its held-out height bias is -33 mm). The world came out 7 % small, and the error depended on
whom the lifter happened to shrink most.

The triangulated people, unlike the lifted ones, have the right sizes relative to each other. So the world is
scaled once more after the bundle adjustment: the sum over the eight limbs (upper and lower arms and legs) of each
limb's median length over the matched groups is set to :data:`REFERENCE_LIMB_SUM_M`, the same figure for the CMU
subjects the lifter learned from. A limb's median over the groups, not each group's sum: a triangulated joint
thrown off by a left-right flip or an outlier lengthens its limbs, and on the demo the median of the groups' sums
came out 6 % over the truth with the true cameras, the sum of the limbs' medians 1.5 %. What is left is how far the
people filmed differ from those adults on average, not a bias of the method.
"""

from __future__ import annotations

import numpy as np

from humancal.keypoints import JOINT_INDEX

__all__ = ["REFERENCE_LIMB_SUM_M", "SCALE_LIMBS", "body_size_ratio", "limb_sums_m", "people_scale_factor"]

REFERENCE_LIMB_SUM_M = 2.61
"""Summed length of the eight limbs of :data:`SCALE_LIMBS` of a reference adult, metres: the median over the CMU
training subjects of the lifter (01, 03, 05-13) of the sum of each limb's median length over the subject's frames
(2.58-2.63 m; the canonical keypoints of their mocap retargeted onto anny), standing 1.65-1.71 m tall (median
1.70 m). Measured by ``python scripts/reference_limbs.py`` (2.616 m)."""

SCALE_LIMBS: tuple[tuple[int, int], ...] = tuple((JOINT_INDEX[a], JOINT_INDEX[b]) for a, b in (
    ("left_hip", "left_knee"), ("left_knee", "left_ankle"), ("right_hip", "right_knee"), ("right_knee", "right_ankle"),
    ("left_shoulder", "left_elbow"), ("left_elbow", "left_wrist"), ("right_shoulder", "right_elbow"),
    ("right_elbow", "right_wrist")))
"""The limbs whose lengths measure a person: (joint, joint) canonical index pairs."""


def limb_sums_m(joints_m: np.ndarray) -> np.ndarray:
    """(...,) summed lengths of :data:`SCALE_LIMBS` of (..., 23, 3) keypoints, metres (NaN where a limb is missing)."""
    joints = np.asarray(joints_m, dtype=np.float64)
    a, b = np.array(SCALE_LIMBS).T
    return np.linalg.norm(joints[..., a, :] - joints[..., b, :], axis=-1).sum(-1)


def people_scale_factor(points_world_m: np.ndarray, reference_limb_sum_m: float = REFERENCE_LIMB_SUM_M,
                        min_people: int = 3) -> tuple[float, int]:
    """The factor that gives the people's limbs (the sum of each limb's median length) the reference's.

    Args:
        points_world_m: (G, 23, 3) triangulated keypoints of the matched groups (one person in one frame), metres.
        reference_limb_sum_m: the reference adult's summed limb length, metres.
        min_people: a limb measured in fewer groups than this leaves the factor at 1 (nothing to measure).

    Returns:
        (factor to multiply the world's lengths by, the fewest groups any limb was measured in).
    """
    joints = np.asarray(points_world_m, dtype=np.float64)
    a, b = np.array(SCALE_LIMBS).T
    lengths = np.linalg.norm(joints[:, a, :] - joints[:, b, :], axis=-1)  # (G, 8)
    measured = np.isfinite(lengths) & (lengths > 0)
    fewest = int(measured.sum(0).min()) if len(lengths) else 0
    if fewest < min_people:
        return 1.0, fewest
    total = sum(float(np.median(lengths[measured[:, k], k])) for k in range(lengths.shape[1]))
    return float(reference_limb_sum_m / total), fewest


def body_size_ratio(points_world_m: np.ndarray, lifted, groups) -> float:
    """Median over the groups of their triangulated limb sums over the median of their detections' lifted ones (about
    1 for cameras that agree with the lifted people; NaN: nothing measurable).

    Args:
        points_world_m: (G, 23, 3) the groups' keypoints, metres.
        lifted: the detections' :class:`~humancal.lifter.LiftedPoses` (any frame: lengths only).
        groups: G arrays of detection rows.
    """
    if not len(groups):
        return float("nan")
    lifted_size = np.array([np.nanmedian(limb_sums_m(lifted.joints_cam_m[g])) for g in groups])
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = limb_sums_m(points_world_m) / lifted_size
    ratio = ratio[np.isfinite(ratio) & (ratio > 0)]
    return float(np.median(ratio)) if len(ratio) else float("nan")
