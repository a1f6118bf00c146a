"""Inputs shared by the calibration steps: lifted 3D poses, the error type, body reference points.

The calibration stage consumes, for every 2D detection, a 3D pose lifted from it: the lifter's
:class:`~humancal.lifter.LiftedPoses` (the canonical 23 keypoints, root-relative, metres, in the detection's
crop or camera frame, plus the person's standing height and an upright-standing score), row-aligned with the
:class:`~humancal.tables.detections.DenseDetections` it was lifted from.
"""

from __future__ import annotations

import numpy as np

from humancal.keypoints import JOINT_INDEX
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = [
    "CalibrationError",
    "LiftedPoses",
    "check_lifted",
    "FACE_JOINTS",
    "FOOT_JOINTS",
    "head_points",
    "ankle_midpoints",
    "hip_midpoints",
    "PLUMB_TOPS",
    "PLUMB_BOTTOMS",
    "plumb_points",
]


class CalibrationError(RuntimeError):
    """Cameras cannot be calibrated from these detections; the message names the view and the reason."""


FACE_JOINTS: tuple[int, ...] = tuple(JOINT_INDEX[n] for n in ("nose", "left_eye", "right_eye", "left_ear", "right_ear"))
"""Canonical indices of the joints whose mean is the "head point" of a person."""

FOOT_JOINTS: tuple[int, ...] = tuple(
    JOINT_INDEX[n]
    for n in ("left_big_toe", "right_big_toe", "left_small_toe", "right_small_toe", "left_heel", "right_heel")
)
"""Canonical indices of the sole points (toes and heels)."""

_ANKLES = (JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"])
_HIPS = (JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"])


def check_lifted(detections: DenseDetections, lifted: LiftedPoses) -> None:
    """Raise ``ValueError`` unless ``lifted`` has one row per detection.

    Raises:
        ValueError: the row counts differ.
    """
    if not isinstance(lifted, LiftedPoses):
        raise ValueError(f"lifted must be a LiftedPoses, got {type(lifted).__name__}")
    if len(lifted) != len(detections):
        raise ValueError(f"lifted has {len(lifted)} rows but there are {len(detections)} detections (one per row)")


def head_points(points: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """The head point of each pose: the mean of its valid face joints (nose, eyes, ears).

    Args:
        points: (N, 23, C) keypoints (C = 2 pixels or 3 metres).
        valid: (N, 23) mask; defaults to finite joints.

    Returns:
        (N, C) head points (NaN where no face joint is valid).
    """
    face = points[:, FACE_JOINTS]
    ok = np.isfinite(face).all(-1) if valid is None else (valid[:, FACE_JOINTS] & np.isfinite(face).all(-1))
    count = ok.sum(1)
    total = np.where(ok[..., None], np.nan_to_num(face), 0.0).sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / count[:, None]
    out[count == 0] = np.nan
    return out


def _pair_midpoints(points: np.ndarray, pair: tuple[int, int], valid: np.ndarray | None) -> np.ndarray:
    mid = 0.5 * (points[:, pair[0]] + points[:, pair[1]])
    if valid is not None:
        mid = np.where((valid[:, pair[0]] & valid[:, pair[1]])[:, None], mid, np.nan)
    return mid


def ankle_midpoints(points: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """(N, C) midpoint of the two ankles (NaN unless both are valid)."""
    return _pair_midpoints(points, _ANKLES, valid)


def hip_midpoints(points: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """(N, C) midpoint of the two hips, the root of lifted poses (NaN unless both are valid)."""
    return _pair_midpoints(points, _HIPS, valid)


def _mean_of(points: np.ndarray, joints: tuple[int, ...], valid: np.ndarray | None, require_all: bool) -> np.ndarray:
    sub = points[:, joints]
    ok = np.isfinite(sub).all(-1) if valid is None else (valid[:, joints] & np.isfinite(sub).all(-1))
    count = ok.sum(1)
    total = np.where(ok[..., None], np.nan_to_num(sub), 0.0).sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / count[:, None]
    bad = (count < len(joints)) if require_all else (count == 0)
    out[bad] = np.nan
    return out


PLUMB_TOPS: dict[str, tuple[tuple[int, ...], bool]] = {
    "head": (FACE_JOINTS, False),
    "ears": ((JOINT_INDEX["left_ear"], JOINT_INDEX["right_ear"]), True),
    "shoulders": ((JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"]), True),
}
"""Top points of a plumb line: joints averaged, and whether all of them are required."""

PLUMB_BOTTOMS: dict[str, tuple[tuple[int, ...], bool]] = {
    "ankles": (_ANKLES, True),
    "feet": (_ANKLES + FOOT_JOINTS, False),
}
"""Bottom points of a plumb line (``"feet"``: mean of the valid ankle, heel and toe points)."""


def plumb_points(
    points: np.ndarray, valid: np.ndarray | None, top: str, bottom: str
) -> tuple[np.ndarray, np.ndarray]:
    """Top and bottom points of each pose's plumb line (a segment that is vertical when standing upright).

    Args:
        points: (N, 23, C) keypoints.
        valid: (N, 23) mask (None: finite joints).
        top: a key of :data:`PLUMB_TOPS`.
        bottom: a key of :data:`PLUMB_BOTTOMS`.

    Returns:
        top_points, bottom_points: (N, C) each (NaN where the joints are missing).
    """
    if top not in PLUMB_TOPS or bottom not in PLUMB_BOTTOMS:
        raise ValueError(f"plumb line {top!r}/{bottom!r}: top must be one of {list(PLUMB_TOPS)}, "
                         f"bottom one of {list(PLUMB_BOTTOMS)}")
    (top_joints, top_all), (bottom_joints, bottom_all) = PLUMB_TOPS[top], PLUMB_BOTTOMS[bottom]
    return _mean_of(points, top_joints, valid, top_all), _mean_of(points, bottom_joints, valid, bottom_all)
