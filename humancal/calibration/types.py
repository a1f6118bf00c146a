"""Inputs shared by the calibration steps: lifted 3D poses, the error type, body reference points.

The calibration stage consumes, for every 2D detection, a 3D pose lifted from it (``LiftedPoses``): the
canonical 23 keypoints in that view's camera frame, root-relative (root = hip midpoint), metres, plus the
person's standing height and an "upright standing" score. Row ``d`` of a :class:`LiftedPoses` belongs to
row ``d`` of the :class:`~humancal.detections.DenseDetections` it was lifted from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.detections import DenseDetections
from humancal.keypoints import JOINT_INDEX, NUM_JOINTS

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


@dataclass(frozen=True)
class LiftedPoses:
    """A 3D pose lifted from every detection (the lifter's output), row-aligned with the detections.

    Attributes:
        joints_cam_m: (D, 23, 3) canonical keypoints relative to the hip midpoint, metres, in the detection's
            camera frame (OpenCV axes), or in its *crop frame* when ``box_centre_px`` is given (the camera frame
            turned by the smallest rotation that brings the ray through the box centre onto the optical axis, as
            ``humancal.lifter`` returns them before the intrinsics are known). May be NaN where not ``valid``.
        height_m: (D,) the person's standing height estimate, metres.
        upright_score: (D,) in [0, 1]: how much the pose is an upright standing one (straight legs and trunk,
            both feet on the floor).
        valid: (D,) whether the detection was lifted (default: all).
        box_centre_px: (D, 2) box centres defining the crop frames, pixels; None when already in camera frames.
    """

    joints_cam_m: np.ndarray
    height_m: np.ndarray
    upright_score: np.ndarray
    valid: np.ndarray | None = None
    box_centre_px: np.ndarray | None = None

    def __post_init__(self) -> None:
        joints = np.asarray(self.joints_cam_m, dtype=np.float64)
        height = np.asarray(self.height_m, dtype=np.float64).reshape(-1)
        upright = np.asarray(self.upright_score, dtype=np.float64).reshape(-1)
        if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
            raise ValueError(f"LiftedPoses.joints_cam_m must have shape (D, {NUM_JOINTS}, 3), got {joints.shape}")
        D = joints.shape[0]
        valid = np.ones(D, bool) if self.valid is None else np.asarray(self.valid, dtype=bool).reshape(-1)
        if height.shape != (D,) or upright.shape != (D,) or valid.shape != (D,):
            raise ValueError(
                f"LiftedPoses: height_m {height.shape}, upright_score {upright.shape} and valid {valid.shape} must "
                f"all be ({D},) like joints_cam_m"
            )
        if not np.isfinite(joints[valid]).all():
            raise ValueError("LiftedPoses.joints_cam_m must be finite in every valid row")
        if not (np.isfinite(height[valid]).all() and (height[valid] > 0).all()):
            raise ValueError("LiftedPoses.height_m must be finite and positive (metres) in every valid row")
        u = upright[valid]
        if not (np.isfinite(u).all() and (u >= 0).all() and (u <= 1).all()):
            raise ValueError("LiftedPoses.upright_score must lie in [0, 1] in every valid row")
        # invalid rows: neutral values, so that no step can pick them up by accident
        joints = np.where(valid[:, None, None], joints, np.nan)
        height = np.where(valid, height, np.nan)
        upright = np.where(valid, upright, 0.0)
        box = None
        if self.box_centre_px is not None:
            box = np.asarray(self.box_centre_px, dtype=np.float64)
            if box.shape != (D, 2) or not np.isfinite(box[valid]).all():
                raise ValueError(f"LiftedPoses.box_centre_px must be finite with shape ({D}, 2), got {box.shape}")
        object.__setattr__(self, "joints_cam_m", joints)
        object.__setattr__(self, "height_m", height)
        object.__setattr__(self, "upright_score", upright)
        object.__setattr__(self, "valid", valid)
        object.__setattr__(self, "box_centre_px", box)

    def __len__(self) -> int:
        return int(self.joints_cam_m.shape[0])

    @property
    def in_crop_frame(self) -> bool:
        """Whether the joints are in the detections' crop frames (``box_centre_px`` given)."""
        return self.box_centre_px is not None

    def subset(self, rows: np.ndarray) -> LiftedPoses:
        """The poses of the given rows (indices or boolean mask)."""
        box = None if self.box_centre_px is None else self.box_centre_px[rows]
        return LiftedPoses(self.joints_cam_m[rows], self.height_m[rows], self.upright_score[rows], self.valid[rows],
                           box)

    def in_camera_frame(self, K_per_detection: np.ndarray) -> LiftedPoses:
        """The poses in their camera frames (a no-op when they already are).

        Args:
            K_per_detection: (D, 3, 3) intrinsics of each detection's view, pixels.
        """
        if self.box_centre_px is None:
            return self
        K = np.asarray(K_per_detection, dtype=np.float64)
        centre = np.where(np.isfinite(self.box_centre_px), self.box_centre_px, 0.0)
        ray = np.linalg.solve(K, np.concatenate([centre, np.ones((len(centre), 1))], axis=1)[..., None])[..., 0]
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        # smallest rotation taking the ray onto +z (crop from camera); its transpose takes crop to camera
        v = np.cross(ray, [0.0, 0.0, 1.0])
        vx = np.zeros((len(ray), 3, 3))
        vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
        vx = vx - vx.transpose(0, 2, 1)
        R_crop_from_cam = np.eye(3) + vx + (vx @ vx) / (1.0 + ray[:, 2])[:, None, None]
        joints = self.joints_cam_m @ R_crop_from_cam  # row vectors: (R^T x)^T = x^T R
        return LiftedPoses(joints, self.height_m, self.upright_score, self.valid, None)

    @classmethod
    def from_lifter(cls, lifted) -> LiftedPoses:
        """Adopt the output of ``humancal.lifter.lift_detections`` (crop or camera frame, with its ``valid``)."""
        box = lifted.box_centre_px if getattr(lifted, "frame", "camera") == "crop" else None
        return cls(lifted.joints_cam_m, lifted.height_m, lifted.upright_score, lifted.valid, box)


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
