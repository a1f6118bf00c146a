"""What the lifter sees and in which frame it answers: box-normalised 2D inputs and the crop frame.

**Inputs.** A detection's confident joints (score > 0) define a box; every joint is expressed relative to the
box centre and divided by half the longer box side, so its coordinates lie in [-1, 1]. A missing joint has
coordinates 0 and confidence 0. The input of one detection is (23, 3): normalised x, normalised y, confidence.
Scaling or shifting the image (a different focal length, principal point or image size) is a 2D similarity of
the keypoints and leaves this input unchanged: the network never sees intrinsics.

**Output frame.** Without intrinsics, the direction from the camera to the person is unknown, and a person at
the image border is seen obliquely (up to half the field of view). The lifter therefore answers in the
detection's *crop frame*: the camera frame turned about the camera centre by the smallest rotation that brings
the ray through the box centre onto the optical axis (a virtual camera looking straight at the person, OpenCV
axes). At the image centre the two frames agree. Once the intrinsics K are known,
:func:`rotate_crop_to_camera` turns crop-frame poses into the camera frame exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.geometry.rotations import rotmat_a_to_b
from humancal.keypoints import NUM_JOINTS, joint_indices

__all__ = [
    "ROOT_JOINTS",
    "NormalizedDetections",
    "check_detections",
    "normalize_detections",
    "root_relative",
    "R_crop_from_cam",
    "rotate_crop_to_camera",
]

ROOT_JOINTS: tuple[int, ...] = tuple(joint_indices(["left_hip", "right_hip"]))
"""The root of every lifted pose is the midpoint of these two joints (the hips)."""


@dataclass(frozen=True)
class NormalizedDetections:
    """Network inputs of D detections.

    Attributes:
        features: (D, 23, 3) float32: box-normalised x, y (in [-1, 1]) and confidence; zeros for missing
            joints and for every joint of an invalid detection.
        box_centre_px: (D, 2) centre of the box of the confident joints, pixels (NaN where invalid).
        box_scale_px: (D,) half the longer side of that box, pixels (NaN where invalid).
        valid: (D,) at least ``min_joints`` confident joints spanning a box of non-zero size.
    """

    features: np.ndarray
    box_centre_px: np.ndarray
    box_scale_px: np.ndarray
    valid: np.ndarray


def check_detections(keypoints_px: np.ndarray, scores: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate dense detections and return them as float64 arrays.

    Args:
        keypoints_px: (D, 23, 2) pixels; entries of joints with score 0 may be anything, NaN included.
        scores: (D, 23) confidences in [0, 1], 0 for a missing joint.

    Returns:
        (keypoints_px, scores) as float64 arrays, keypoints of missing joints set to NaN.

    Raises:
        ValueError: wrong shapes, non-finite or out-of-range scores, or a non-finite position of a joint with
            a positive score.
    """
    kp = np.asarray(keypoints_px, dtype=np.float64)
    sc = np.asarray(scores, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[1:] != (NUM_JOINTS, 2):
        raise ValueError(f"keypoints_px must have shape (D, {NUM_JOINTS}, 2), got {kp.shape}")
    if sc.shape != kp.shape[:2]:
        raise ValueError(f"scores must have shape {kp.shape[:2]} (one per keypoint), got {sc.shape}")
    if not np.isfinite(sc).all():
        raise ValueError("scores must be finite (0 marks a missing joint)")
    if sc.size and (sc.min() < 0.0 or sc.max() > 1.0):
        raise ValueError(f"scores must lie in [0, 1], got values in [{sc.min():.3g}, {sc.max():.3g}]")
    present = sc > 0.0
    bad = present & ~np.isfinite(kp).all(-1)
    if bad.any():
        d, j = np.argwhere(bad)[0]
        raise ValueError(
            f"keypoints_px has non-finite positions for {int(bad.sum())} joint(s) with a positive score "
            f"(first: detection {d}, joint {j}); give missing joints score 0"
        )
    return np.where(present[..., None], kp, np.nan), sc


def normalize_detections(keypoints_px: np.ndarray, scores: np.ndarray, min_joints: int = 4) -> NormalizedDetections:
    """Box-normalised network inputs (see the module docstring).

    Args:
        keypoints_px: (D, 23, 2) pixels (NaN or anything where the score is 0).
        scores: (D, 23) confidences in [0, 1], 0 for missing joints.
        min_joints: a detection needs at least this many confident joints to be valid.

    Returns:
        The :class:`NormalizedDetections`.

    Raises:
        ValueError: bad shapes or values (see :func:`check_detections`), or ``min_joints`` < 2.
    """
    if min_joints < 2:
        raise ValueError(f"min_joints={min_joints} must be >= 2 (a box needs two points)")
    kp, sc = check_detections(keypoints_px, scores)
    present = sc > 0.0
    with np.errstate(invalid="ignore"):
        low = np.nanmin(np.where(present[..., None], kp, np.inf), axis=1)
        high = np.nanmax(np.where(present[..., None], kp, -np.inf), axis=1)
        centre = 0.5 * (low + high)
        scale = 0.5 * (high - low).max(axis=1)
    valid = (present.sum(axis=1) >= min_joints) & np.isfinite(scale) & (scale > 1e-6)
    centre = np.where(valid[:, None], centre, np.nan)
    scale = np.where(valid, scale, np.nan)
    features = np.zeros(kp.shape[:2] + (3,), dtype=np.float64)
    use = present & valid[:, None]
    with np.errstate(invalid="ignore"):
        xy = (kp - centre[:, None, :]) / scale[:, None, None]
    features[..., :2] = np.where(use[..., None], xy, 0.0)
    features[..., 2] = np.where(use, sc, 0.0)
    return NormalizedDetections(features.astype(np.float32), centre, scale, valid)


def root_relative(joints_m: np.ndarray) -> np.ndarray:
    """Subtract the root (hip midpoint) from every joint.

    Args:
        joints_m: (..., 23, 3) metres.

    Returns:
        (..., 23, 3) joints relative to the hip midpoint, metres.
    """
    joints_m = np.asarray(joints_m)
    return joints_m - joints_m[..., list(ROOT_JOINTS), :].mean(axis=-2, keepdims=True)


def _broadcast_K(K: np.ndarray, num: int) -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape == (3, 3):
        K = np.broadcast_to(K, (num, 3, 3))
    if K.shape != (num, 3, 3):
        raise ValueError(f"K must have shape (3, 3) or ({num}, 3, 3), got {K.shape}")
    if not np.isfinite(K).all():
        raise ValueError("K must be finite")
    return K


def R_crop_from_cam(box_centre_px: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Rotation from the camera frame to each detection's crop frame.

    The smallest rotation taking the ray through the box centre onto the optical axis +z (about the axis
    ``ray x z``).

    Args:
        box_centre_px: (D, 2) box centres, pixels.
        K: (3, 3) or (D, 3, 3) intrinsics, pixels.

    Returns:
        (D, 3, 3) ``R_crop_from_cam`` (NaN rows where the box centre is NaN).

    Raises:
        ValueError: bad shapes or a non-finite K.
    """
    centre = np.asarray(box_centre_px, dtype=np.float64)
    if centre.ndim != 2 or centre.shape[1] != 2:
        raise ValueError(f"box_centre_px must have shape (D, 2), got {centre.shape}")
    K = _broadcast_K(K, centre.shape[0])
    homogeneous = np.concatenate([centre, np.ones((centre.shape[0], 1))], axis=1)
    ray = np.linalg.solve(K, homogeneous[..., None])[..., 0]
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    # a person in view has ray . z > 0, far from the one singular case (opposite directions)
    return rotmat_a_to_b(ray, np.array([0.0, 0.0, 1.0]))


def rotate_crop_to_camera(joints_crop_m: np.ndarray, box_centre_px: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Turn crop-frame poses into the camera frame (exact, given the intrinsics).

    Args:
        joints_crop_m: (D, 23, 3) root-relative joints in the crop frame, metres.
        box_centre_px: (D, 2) the box centres the crop frames were built from, pixels.
        K: (3, 3) or (D, 3, 3) intrinsics, pixels.

    Returns:
        (D, 23, 3) root-relative joints in the camera frame, metres.

    Raises:
        ValueError: bad shapes.
    """
    joints = np.asarray(joints_crop_m, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f"joints_crop_m must have shape (D, {NUM_JOINTS}, 3), got {joints.shape}")
    R = R_crop_from_cam(box_centre_px, K)
    if R.shape[0] != joints.shape[0]:
        raise ValueError(f"box_centre_px has {R.shape[0]} rows but joints_crop_m has {joints.shape[0]}")
    return joints @ R  # row vectors: (R^T x)^T = x^T R
