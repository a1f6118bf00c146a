"""The lifted 3D poses of a set of detections: the one type the lifter returns and the calibration reads.

Row ``d`` of a :class:`LiftedPoses` belongs to row ``d`` of the
:class:`~humancal.tables.detections.DenseDetections` it was lifted from. Poses come in each detection's *crop frame*
(``humancal.lifter.features``: the camera frame turned to look straight at the detection's box centre) while
the intrinsics are unknown, and in the view's camera frame once :meth:`LiftedPoses.in_camera_frame` has turned
them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from humancal.keypoints import NUM_JOINTS
from humancal.lifter.features import rotate_crop_to_camera

__all__ = ["LiftedPoses"]

_FRAMES = ("crop", "camera")


@dataclass(frozen=True)
class LiftedPoses:
    """One lifted 3D pose per detection, row-aligned with the detections.

    Attributes:
        joints_cam_m: (D, 23, 3) canonical keypoints relative to the hip midpoint, metres, in the frame named by
            ``frame`` (NaN rows where not ``valid``).
        height_m: (D,) the person's standing height estimate, metres, finite and positive where valid (NaN
            where not).
        upright_score: (D,) in [0, 1] where valid (NaN where not): how much the pose is an upright standing
            one (:func:`humancal.lifter.upright_score` of the pose as lifted, for the lifter's output).
        valid: (D,) whether the detection was lifted (default: all).
        box_centre_px: (D, 2) box centres defining the crop frames, pixels (required for ``frame="crop"``).
        frame: ``"crop"`` (each detection's crop frame) or ``"camera"`` (the view's camera frame, OpenCV axes).
    """

    joints_cam_m: np.ndarray
    height_m: np.ndarray
    upright_score: np.ndarray
    valid: np.ndarray | None = None
    box_centre_px: np.ndarray | None = None
    frame: Literal["crop", "camera"] = "camera"

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
        if self.frame not in _FRAMES:
            raise ValueError(f"LiftedPoses.frame={self.frame!r}; allowed: {_FRAMES}")
        if not np.isfinite(joints[valid]).all():
            raise ValueError("LiftedPoses.joints_cam_m must be finite in every valid row")
        if not (np.isfinite(height[valid]).all() and (height[valid] > 0).all()):
            raise ValueError("LiftedPoses.height_m must be finite and positive (metres) in every valid row")
        u = upright[valid]
        if not (np.isfinite(u).all() and (u >= 0).all() and (u <= 1).all()):
            raise ValueError("LiftedPoses.upright_score must lie in [0, 1] in every valid row")
        box = None
        if self.box_centre_px is not None:
            box = np.asarray(self.box_centre_px, dtype=np.float64)
            if box.shape != (D, 2) or not np.isfinite(box[valid]).all():
                raise ValueError(f"LiftedPoses.box_centre_px must be finite with shape ({D}, 2) in every valid row, "
                                 f"got {box.shape}")
        elif self.frame == "crop":
            raise ValueError("LiftedPoses in crop frames need box_centre_px (the crop frames' box centres)")
        # rows that were not lifted hold NaN, so that no step can pick them up by accident
        object.__setattr__(self, "joints_cam_m", np.where(valid[:, None, None], joints, np.nan))
        object.__setattr__(self, "height_m", np.where(valid, height, np.nan))
        object.__setattr__(self, "upright_score", np.where(valid, upright, np.nan))
        object.__setattr__(self, "valid", valid)
        object.__setattr__(self, "box_centre_px", box)

    def __len__(self) -> int:
        return int(self.joints_cam_m.shape[0])

    def subset(self, rows: np.ndarray) -> LiftedPoses:
        """The poses of the given rows (indices or boolean mask)."""
        box = None if self.box_centre_px is None else self.box_centre_px[rows]
        return LiftedPoses(self.joints_cam_m[rows], self.height_m[rows], self.upright_score[rows], self.valid[rows],
                           box, self.frame)

    def in_camera_frame(self, K: np.ndarray) -> LiftedPoses:
        """The same poses turned into the camera frame (a no-op when they already are).

        Heights and upright scores are kept as they are (a rotation keeps lengths; the score stays the one the
        pose was lifted with).

        Args:
            K: (3, 3) or (D, 3, 3) intrinsics of each detection's view, pixels.

        Raises:
            ValueError: bad shape of K.
        """
        if self.frame == "camera":
            return self
        K = np.asarray(K, dtype=np.float64)
        if K.shape not in ((3, 3), (len(self), 3, 3)):
            raise ValueError(f"K must have shape (3, 3) or ({len(self)}, 3, 3), got {K.shape}")
        joints = np.full_like(self.joints_cam_m, np.nan)
        v = self.valid
        if v.any():
            joints[v] = rotate_crop_to_camera(self.joints_cam_m[v], self.box_centre_px[v], K if K.ndim == 2 else K[v])
        return LiftedPoses(joints, self.height_m, self.upright_score, v, self.box_centre_px, "camera")
