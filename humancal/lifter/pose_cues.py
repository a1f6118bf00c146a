"""Cues read from one 3D pose: the person's standing height and how much the pose is a standing, upright one.

Both work on the canonical 23 keypoints of any pose (lifted or true) and need no camera, except that
:func:`upright_score` reads "vertical" as the camera's up axis (-y, OpenCV).
"""

from __future__ import annotations

import numpy as np

from humancal.geometry.rotations import angle_between_deg
from humancal.keypoints import JOINT_INDEX, NUM_JOINTS

__all__ = [
    "HEIGHT_CHAIN_FACTOR",
    "HEIGHT_OFFSET_M",
    "height_chain_m",
    "height_from_pose_m",
    "standing_score",
    "upright_score",
]

HEIGHT_CHAIN_FACTOR = 1.0977
"""Standing height per metre of the ankle-knee-hip-shoulder-ear chain (see :func:`height_from_pose_m`)."""
HEIGHT_OFFSET_M = 0.0691
"""Constant part of the standing height, metres (see :func:`height_from_pose_m`)."""

_J = JOINT_INDEX


def _check_joints(joints_m: np.ndarray, name: str) -> np.ndarray:
    joints = np.asarray(joints_m, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f"{name} must have shape (D, {NUM_JOINTS}, 3), got {joints.shape}")
    return joints


def _mid(joints: np.ndarray, a: str, b: str) -> np.ndarray:
    return 0.5 * (joints[:, _J[a]] + joints[:, _J[b]])


def _dist(joints: np.ndarray, a: str, b: str) -> np.ndarray:
    return np.linalg.norm(joints[:, _J[a]] - joints[:, _J[b]], axis=-1)


def height_chain_m(joints_m: np.ndarray) -> np.ndarray:
    """Length of the body's vertical chain, a pose-independent size measure.

    Shin (ankle-knee) and thigh (knee-hip), each the mean of left and right, plus the trunk (hip midpoint to
    shoulder midpoint) and the neck (shoulder midpoint to ear midpoint).

    Args:
        joints_m: (D, 23, 3) canonical keypoints in any frame, metres.

    Returns:
        (D,) chain length, metres (NaN where a needed joint is NaN).

    Raises:
        ValueError: wrong shape.
    """
    joints = _check_joints(joints_m, "joints_m")
    shin = 0.5 * (_dist(joints, "left_ankle", "left_knee") + _dist(joints, "right_ankle", "right_knee"))
    thigh = 0.5 * (_dist(joints, "left_knee", "left_hip") + _dist(joints, "right_knee", "right_hip"))
    shoulders = _mid(joints, "left_shoulder", "right_shoulder")
    trunk = np.linalg.norm(shoulders - _mid(joints, "left_hip", "right_hip"), axis=-1)
    neck = np.linalg.norm(_mid(joints, "left_ear", "right_ear") - shoulders, axis=-1)
    return shin + thigh + trunk + neck


def height_from_pose_m(joints_m: np.ndarray) -> np.ndarray:
    """Standing height (soles to the top of the head) estimated from the segment lengths of any pose.

    ``height = HEIGHT_CHAIN_FACTOR * height_chain_m(joints) + HEIGHT_OFFSET_M``. The chain misses the ankle
    height above the soles (about 10 cm) and the head above the ears (about 13 cm); both grow with body size,
    hence a factor and an offset. Calibrated by least squares on 1,000 anny adults of standing height 1.40 to
    2.00 m (``humancal.synthetic.sample_people``, varied build) in the identity pose, against
    ``BodyModel.height_m``: RMS error 8 mm, largest 16 mm. On posed bodies (8 people, 900 frames of the
    synthetic activities: walking, turning, standing, gestures, crouching) skinned keypoints move a little:
    error bias -1.8 cm, std 2.8 cm, largest 11 cm (deep crouches shorten the trunk).

    Args:
        joints_m: (D, 23, 3) canonical keypoints in any frame, metres.

    Returns:
        (D,) heights, metres (NaN where a needed joint is NaN).

    Raises:
        ValueError: wrong shape.
    """
    return HEIGHT_CHAIN_FACTOR * height_chain_m(joints_m) + HEIGHT_OFFSET_M


def _falling_ramp(x: np.ndarray, full: float, zero: float) -> np.ndarray:
    """1 for x <= full, 0 for x >= zero, smoothstep in between (NaN stays NaN)."""
    t = np.clip((x - full) / (zero - full), 0.0, 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


UPRIGHT_RAMPS_DEG = {
    "knee_bend": (15.0, 35.0),
    "hip_bend": (15.0, 30.0),
    "side_lean": (8.0, 20.0),
    "tilt": (40.0, 70.0),
}
"""(full score, zero score) of each angle of :func:`upright_score` and :func:`standing_score`, degrees."""
UPRIGHT_FOOT_STEP_M = (0.05, 0.15)
"""(full score, zero score) of the ankle height difference along the body axis, metres."""


def _body_axis(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body axis (ankle midpoint to shoulder midpoint) and its unit vector (NaN where degenerate)."""
    axis = _mid(joints, "left_shoulder", "right_shoulder") - _mid(joints, "left_ankle", "right_ankle")
    with np.errstate(invalid="ignore", divide="ignore"):
        return axis, axis / np.linalg.norm(axis, axis=-1, keepdims=True)


def standing_score(joints_m: np.ndarray) -> np.ndarray:
    """How much each pose is a standing one, in [0, 1], from body-internal geometry only (any frame).

    The body-internal factors of :func:`upright_score`, each 1 up to a "full" value and falling smoothly
    (smoothstep) to 0 at a "zero" value: knees extended (:data:`UPRIGHT_RAMPS_DEG` ``knee_bend``), hips
    extended (``hip_bend``) and both feet down (:data:`UPRIGHT_FOOT_STEP_M`). It needs no camera, so it also
    judges reconstructed world poses and poses whose camera is unknown.

    Args:
        joints_m: (D, 23, 3) canonical keypoints in any frame, metres.

    Returns:
        (D,) scores in [0, 1] (NaN where a needed joint is NaN).

    Raises:
        ValueError: wrong shape.
    """
    joints = _check_joints(joints_m, "joints_m")
    hips = _mid(joints, "left_hip", "right_hip")
    shoulders = _mid(joints, "left_shoulder", "right_shoulder")
    knee_bend, hip_bend = [], []
    for side in ("left", "right"):
        thigh = joints[:, _J[f"{side}_knee"]] - joints[:, _J[f"{side}_hip"]]
        shin = joints[:, _J[f"{side}_ankle"]] - joints[:, _J[f"{side}_knee"]]
        knee_bend.append(angle_between_deg(thigh, shin))
        hip_bend.append(angle_between_deg(hips - shoulders, thigh))
    _, axis_unit = _body_axis(joints)
    step = np.abs(((joints[:, _J["left_ankle"]] - joints[:, _J["right_ankle"]]) * axis_unit).sum(-1))
    score = _falling_ramp(np.maximum(*knee_bend), *UPRIGHT_RAMPS_DEG["knee_bend"])
    score = score * _falling_ramp(np.maximum(*hip_bend), *UPRIGHT_RAMPS_DEG["hip_bend"])
    return score * _falling_ramp(step, *UPRIGHT_FOOT_STEP_M)


def upright_score(joints_cam_m: np.ndarray) -> np.ndarray:
    """How much each pose is an upright standing one, in [0, 1], from a pose in a camera frame (y down).

    :func:`standing_score` (knees and hips extended, both feet down) times two factors that read the camera's
    vertical, each 1 up to a "full" value and falling smoothly (smoothstep) to 0 at a "zero" value
    (:data:`UPRIGHT_RAMPS_DEG`):

    * no sideways lean in the image: with ``a`` the body axis (ankle midpoint to shoulder midpoint),
      ``asin(|a_x| / |a|)``, 8 -> 20 deg;
    * body axis near the camera's up direction -y: the angle between ``a`` and -y, 40 -> 70 deg. The wide
      tolerance admits cameras pitched down or up by up to about 40 deg, whose view of an upright person is
      tilted in the camera's y-z plane.

    The standing factors: the larger angle between thigh (hip to knee) and shin (knee to ankle), 15 -> 35 deg;
    the larger angle between the trunk (shoulder midpoint to hip midpoint) and a thigh, 15 -> 30 deg; the
    difference of the two ankles along the body axis, 5 -> 15 cm.

    Args:
        joints_cam_m: (D, 23, 3) canonical keypoints in a camera frame (OpenCV: y down), metres; root-relative
            or not.

    Returns:
        (D,) scores in [0, 1] (NaN where a needed joint is NaN).

    Raises:
        ValueError: wrong shape.
    """
    joints = _check_joints(joints_cam_m, "joints_cam_m")
    axis, axis_unit = _body_axis(joints)
    side_lean = np.degrees(np.arcsin(np.clip(np.abs(axis_unit[:, 0]), 0.0, 1.0)))
    tilt = angle_between_deg(axis, np.array([0.0, -1.0, 0.0]))
    score = standing_score(joints) * _falling_ramp(side_lean, *UPRIGHT_RAMPS_DEG["side_lean"])
    return score * _falling_ramp(tilt, *UPRIGHT_RAMPS_DEG["tilt"])
