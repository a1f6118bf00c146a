"""Keypoint formats ("skeletons") of detectors and datasets, by name.

Every skeleton lists its joints in the format's array order, with names from one vocabulary: the canonical names
of :mod:`humancal.keypoints` (``left_shoulder``, ``right_big_toe``, ...) for the joints the canonical set has, and
a few more for the joints it lacks:

``neck``
    between the shoulders (OpenPose ``Neck``, Halpe ``Neck``, CMU Panoptic ``Neck``).
``mid_hip``
    between the hips (OpenPose ``MidHip``, Halpe ``Hip``, CMU Panoptic ``BodyCenter``).
``pelvis``
    between the hips, as Shelf/Campus ground truth names it (SHELF15 joint 14).
``bottom_head``, ``top_head``
    Shelf/Campus head joints (SHELF15 joints 12 and 13); ``top_head`` is also Halpe's ``Head`` and OpenPose
    BODY_25B's ``HeadTop``.
``upper_neck``
    the top of the neck, under the chin (OpenPose BODY_25B ``UpperNeck``).
``face_NN``, ``left_hand_NN``, ``right_hand_NN``
    the face and hand points of COCO-WholeBody (never used downstream).

A joint with the same name in two skeletons is the same anatomical point, which is what the mapping to and
from the canonical set (:mod:`humancal.formats.joint_mapping`) relies on.
"""

from __future__ import annotations

from dataclasses import dataclass

from humancal.keypoints import CANONICAL_JOINTS, LIMBS

__all__ = ["Skeleton", "SKELETONS", "get_skeleton"]


@dataclass(frozen=True)
class Skeleton:
    """A keypoint format: joint names in array order, the bones between them and their left/right twins.

    Attributes:
        name: registry name (``"body25"``, ``"shelf15"``, ...).
        joints: (J,) joint names in the format's array order.
        limbs: bones as pairs of joint names (for drawing and limb metrics).
        left_right: (left, right) pairs of joint names swapped by a mirror image.
        description: where the format comes from, in words.
    """

    name: str
    joints: tuple[str, ...]
    limbs: tuple[tuple[str, str], ...]
    left_right: tuple[tuple[str, str], ...]
    description: str = ""

    def __post_init__(self) -> None:
        if len(set(self.joints)) != len(self.joints):
            duplicated = sorted({j for j in self.joints if self.joints.count(j) > 1})
            raise ValueError(f"skeleton '{self.name}': joint names must be unique, repeated {duplicated}")
        known = set(self.joints)
        for kind, pairs in (("limbs", self.limbs), ("left_right", self.left_right)):
            unknown = sorted({n for pair in pairs for n in pair if n not in known})
            if unknown:
                raise ValueError(f"skeleton '{self.name}': {kind} name joint(s) {unknown} that are not in its joints")

    @property
    def num_joints(self) -> int:
        """J, the number of joints."""
        return len(self.joints)

    def index(self, joint: str) -> int:
        """Array index of ``joint``.

        Raises:
            ValueError: the skeleton has no such joint (the message lists its joints).
        """
        try:
            return self.joints.index(joint)
        except ValueError:
            joints = list(self.joints)
            raise ValueError(f"skeleton '{self.name}' has no joint '{joint}'; its joints are {joints}") from None

    @property
    def limb_index(self) -> tuple[tuple[int, int], ...]:
        """``limbs`` as pairs of array indices."""
        return tuple((self.index(a), self.index(b)) for a, b in self.limbs)

    @property
    def flip_index(self) -> tuple[int, ...]:
        """``keypoints[..., flip_index, :]`` swaps every left joint with its right twin."""
        swap = {a: b for a, b in self.left_right} | {b: a for a, b in self.left_right}
        return tuple(self.index(swap.get(j, j)) for j in self.joints)


def _left_right_pairs(joints: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    """(left_x, right_x) for every ``left_x`` whose ``right_x`` is also a joint."""
    twins = [(j, "right_" + j[len("left_") :]) for j in joints if j.startswith("left_")]
    return tuple((left, right) for left, right in twins if right in joints)


def _skeleton(name: str, joints: tuple[str, ...], limbs: tuple[tuple[str, str], ...], description: str) -> Skeleton:
    return Skeleton(name, joints, limbs, _left_right_pairs(joints), description)


def _sides(*pairs: tuple[str, str]) -> tuple[tuple[str, str], ...]:
    """Each ``("X", "Y")`` pair with ``{side}`` placeholders, written once for the left and once for the right side."""
    return tuple((a.format(side=s), b.format(side=s)) for s in ("left", "right") for a, b in pairs)


_ARM = (("{side}_shoulder", "{side}_elbow"), ("{side}_elbow", "{side}_wrist"))
_LEG = (("{side}_hip", "{side}_knee"), ("{side}_knee", "{side}_ankle"))
_FACE = (("nose", "{side}_eye"), ("{side}_eye", "{side}_ear"))
_FOOT = (("{side}_ankle", "{side}_heel"), ("{side}_ankle", "{side}_big_toe"), ("{side}_big_toe", "{side}_small_toe"))

_BODY25_JOINTS = (
    "nose", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder", "left_elbow", "left_wrist",
    "mid_hip", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle",
    "right_eye", "left_eye", "right_ear", "left_ear",
    "left_big_toe", "left_small_toe", "left_heel", "right_big_toe", "right_small_toe", "right_heel",
)  # fmt: skip

_BODY25B_JOINTS = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle",
) + (
    "upper_neck", "top_head",
    "left_big_toe", "left_small_toe", "left_heel", "right_big_toe", "right_small_toe", "right_heel",
)  # fmt: skip
"""OpenPose's experimental BODY_25B model: the COCO-17 points in COCO order, then upper neck, head top and the
6 foot points. Also 25 points, but in another order than BODY_25: never tell them apart by length alone."""

_COCO18_JOINTS = (
    "nose", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder", "left_elbow", "left_wrist",
    "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle",
    "right_eye", "left_eye", "right_ear", "left_ear",
)  # fmt: skip

_COCO17_JOINTS = CANONICAL_JOINTS[:17]

_HALPE26_JOINTS = _COCO17_JOINTS + (
    "top_head", "neck", "mid_hip",
    "left_big_toe", "right_big_toe", "left_small_toe", "right_small_toe", "left_heel", "right_heel",
)  # fmt: skip

_SHELF15_JOINTS = (
    "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle",
    "right_wrist", "right_elbow", "right_shoulder", "left_shoulder", "left_elbow", "left_wrist",
    "bottom_head", "top_head", "pelvis",
)  # fmt: skip

_PANOPTIC19_JOINTS = (
    "neck", "nose", "mid_hip",
    "left_shoulder", "left_elbow", "left_wrist", "left_hip", "left_knee", "left_ankle",
    "right_shoulder", "right_elbow", "right_wrist", "right_hip", "right_knee", "right_ankle",
    "left_eye", "left_ear", "right_eye", "right_ear",
)  # fmt: skip

_WHOLEBODY133_JOINTS = (
    _COCO17_JOINTS
    + ("left_big_toe", "left_small_toe", "left_heel", "right_big_toe", "right_small_toe", "right_heel")
    + tuple(f"face_{i:02d}" for i in range(68))
    + tuple(f"left_hand_{i:02d}" for i in range(21))
    + tuple(f"right_hand_{i:02d}" for i in range(21))
)

_COCO17_LIMBS = (
    _sides(*_ARM, *_LEG, *_FACE, ("{side}_shoulder", "{side}_hip"), ("{side}_ear", "{side}_shoulder"))
    + (("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"), ("left_eye", "right_eye"))
)

SKELETONS: dict[str, Skeleton] = {
    s.name: s
    for s in (
        _skeleton(
            "body25",
            _BODY25_JOINTS,
            _sides(*_ARM, *_LEG, *_FACE, *_FOOT, ("neck", "{side}_shoulder"), ("mid_hip", "{side}_hip"))
            + (("neck", "nose"), ("neck", "mid_hip")),
            "OpenPose BODY_25 (pose_keypoints_2d of the BODY_25 model): COCO joints + neck, mid-hip and 6 foot points",
        ),
        _skeleton(
            "body25b",
            _BODY25B_JOINTS,
            _COCO17_LIMBS + _sides(*_FOOT) + (("upper_neck", "top_head"),)
            + _sides(("upper_neck", "{side}_shoulder")),
            "OpenPose BODY_25B (experimental model): COCO-17 in COCO order + upper neck, head top and 6 foot points",
        ),
        _skeleton(
            "coco18",
            _COCO18_JOINTS,
            _sides(*_ARM, *_LEG, *_FACE, ("neck", "{side}_shoulder"), ("neck", "{side}_hip")) + (("neck", "nose"),),
            "OpenPose COCO model (18 joints: the COCO-17 points in OpenPose order plus the neck)",
        ),
        _skeleton("coco17", _COCO17_JOINTS, _COCO17_LIMBS, "MS-COCO person keypoints (17)"),
        _skeleton(
            "halpe26",
            _HALPE26_JOINTS,
            _COCO17_LIMBS + _sides(*_FOOT, ("mid_hip", "{side}_hip")) + (("neck", "top_head"), ("neck", "mid_hip")),
            "Halpe full-body 26 (AlphaPose): COCO-17 + head top, neck, mid-hip and 6 foot points",
        ),
        _skeleton(
            "shelf15",
            _SHELF15_JOINTS,
            _sides(*_ARM, *_LEG, ("bottom_head", "{side}_shoulder"), ("pelvis", "{side}_hip"))
            + (("bottom_head", "top_head"), ("bottom_head", "pelvis")),
            "Shelf/Campus ground truth as 4D Association ships it: the usual 14 joints + pelvis",
        ),
        _skeleton(
            "shelf14",
            _SHELF15_JOINTS[:14],
            _sides(*_ARM, *_LEG, ("bottom_head", "{side}_shoulder"), ("{side}_shoulder", "{side}_hip"))
            + (("bottom_head", "top_head"), ("left_hip", "right_hip")),
            "Shelf ground truth, 14 joints (the first 14 of SHELF15)",
        ),
        _skeleton(
            "campus14",
            _SHELF15_JOINTS[:14],
            _sides(*_ARM, *_LEG, ("bottom_head", "{side}_shoulder"), ("{side}_shoulder", "{side}_hip"))
            + (("bottom_head", "top_head"), ("left_hip", "right_hip")),
            "Campus ground truth, 14 joints (same order as Shelf's)",
        ),
        _skeleton(
            "panoptic19",
            _PANOPTIC19_JOINTS,
            _sides(*_ARM, *_LEG, *_FACE, ("neck", "{side}_shoulder"), ("mid_hip", "{side}_hip"))
            + (("neck", "nose"), ("neck", "mid_hip")),
            "CMU Panoptic joints19 (neck, nose, body centre, left arm/leg, right arm/leg, left eye/ear, right eye/ear)",
        ),
        _skeleton(
            "coco_wholebody133",
            _WHOLEBODY133_JOINTS,
            _COCO17_LIMBS + _sides(*_FOOT),
            "COCO-WholeBody 133: COCO-17, 6 foot points, 68 face, 21 + 21 hand points",
        ),
        _skeleton("canonical23", CANONICAL_JOINTS, LIMBS, "humancal's canonical set: COCO-17 + 6 foot points"),
    )
}
"""Every supported keypoint format, by name."""


def get_skeleton(skeleton: str | Skeleton) -> Skeleton:
    """The skeleton named ``skeleton`` (a :class:`Skeleton` is returned as is).

    Raises:
        ValueError: unknown name (the message lists the known ones).
    """
    if isinstance(skeleton, Skeleton):
        return skeleton
    try:
        return SKELETONS[skeleton]
    except (KeyError, TypeError):
        raise ValueError(f"unknown skeleton {skeleton!r}; known skeletons are {sorted(SKELETONS)}") from None

