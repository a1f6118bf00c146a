"""The canonical 23-point keypoint set used by every table and stage of humancal.

COCO-17 in its usual order, then six foot points (big toes, small toes, heels; left before right),
exactly the order of ``anny.KeypointsRegressor.coco`` (so body-model keypoints need no reordering). Readers of other formats map onto this set
(``humancal.formats.skeletons``); nothing downstream sees any other joint order.
"""

from __future__ import annotations

CANONICAL_JOINTS: tuple[str, ...] = (
    "nose",
    "left_eye",
    "right_eye",
    "left_ear",
    "right_ear",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_big_toe",
    "right_big_toe",
    "left_small_toe",
    "right_small_toe",
    "left_heel",
    "right_heel",
)
"""Names of the canonical keypoints, in array order."""

NUM_JOINTS = len(CANONICAL_JOINTS)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(CANONICAL_JOINTS)}


def _mirror_name(name: str) -> str:
    if name.startswith("left_"):
        return "right_" + name[len("left_") :]
    if name.startswith("right_"):
        return "left_" + name[len("right_") :]
    return name


FLIP_INDEX: tuple[int, ...] = tuple(JOINT_INDEX[_mirror_name(n)] for n in CANONICAL_JOINTS)
"""``keypoints[..., FLIP_INDEX, :]`` swaps every left joint with its right twin."""

LIMBS: tuple[tuple[str, str], ...] = (
    ("left_shoulder", "left_elbow"),
    ("left_elbow", "left_wrist"),
    ("right_shoulder", "right_elbow"),
    ("right_elbow", "right_wrist"),
    ("left_hip", "left_knee"),
    ("left_knee", "left_ankle"),
    ("right_hip", "right_knee"),
    ("right_knee", "right_ankle"),
    ("left_shoulder", "right_shoulder"),
    ("left_hip", "right_hip"),
    ("left_shoulder", "left_hip"),
    ("right_shoulder", "right_hip"),
    ("nose", "left_eye"),
    ("nose", "right_eye"),
    ("left_eye", "left_ear"),
    ("right_eye", "right_ear"),
    ("left_ankle", "left_heel"),
    ("left_heel", "left_big_toe"),
    ("left_big_toe", "left_small_toe"),
    ("right_ankle", "right_heel"),
    ("right_heel", "right_big_toe"),
    ("right_big_toe", "right_small_toe"),
)
"""Bones drawn in plots and scored by the canonical-set PCP (pairs of joint names)."""

LIMB_INDEX: tuple[tuple[int, int], ...] = tuple((JOINT_INDEX[a], JOINT_INDEX[b]) for a, b in LIMBS)


def joint_indices(names: list[str] | tuple[str, ...]) -> list[int]:
    """Indices of canonical joints by name.

    Raises:
        ValueError: a name is not a canonical joint (the message lists the valid names).
    """
    unknown = [n for n in names if n not in JOINT_INDEX]
    if unknown:
        raise ValueError(f"unknown joint name(s) {unknown}; canonical joints are {list(CANONICAL_JOINTS)}")
    return [JOINT_INDEX[n] for n in names]
