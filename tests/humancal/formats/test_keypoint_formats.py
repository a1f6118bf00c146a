"""The keypoint-format registry: joint orders, limbs, left/right twins."""

from __future__ import annotations

import pytest

from humancal.formats.skeletons import SKELETONS, Skeleton, get_skeleton
from humancal.keypoints import CANONICAL_JOINTS, FLIP_INDEX

EXPECTED_COUNTS = {
    "body25": 25,
    "body25b": 25,
    "coco18": 18,
    "coco17": 17,
    "halpe26": 26,
    "shelf15": 15,
    "shelf14": 14,
    "campus14": 14,
    "panoptic19": 19,
    "coco_wholebody133": 133,
    "canonical23": 23,
}


def test_registry_holds_every_format_with_its_joint_count():
    assert {name: s.num_joints for name, s in SKELETONS.items()} == EXPECTED_COUNTS


def test_body25b_is_coco_order_then_neck_head_and_feet():
    body25b = SKELETONS["body25b"]
    assert body25b.joints[:17] == CANONICAL_JOINTS[:17]
    assert body25b.joints[17:19] == ("upper_neck", "top_head")
    assert body25b.joints[19:] == SKELETONS["body25"].joints[19:]  # the foot points share BODY_25's order
    assert body25b.index("left_eye") == 1 and SKELETONS["body25"].index("neck") == 1  # same length, other order


def test_shelf15_order_is_the_ground_truth_order():
    assert SKELETONS["shelf15"].joints == (
        "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle",
        "right_wrist", "right_elbow", "right_shoulder", "left_shoulder", "left_elbow", "left_wrist",
        "bottom_head", "top_head", "pelvis",
    )  # fmt: skip
    assert SKELETONS["shelf14"].joints == SKELETONS["shelf15"].joints[:14]
    assert SKELETONS["campus14"].joints == SKELETONS["shelf14"].joints


@pytest.mark.parametrize(
    "name, index, joint",
    [
        ("body25", 1, "neck"),
        ("body25", 8, "mid_hip"),
        ("body25", 11, "right_ankle"),
        ("body25", 15, "right_eye"),
        ("body25", 19, "left_big_toe"),
        ("body25", 24, "right_heel"),
        ("coco18", 1, "neck"),
        ("coco18", 8, "right_hip"),
        ("coco18", 17, "left_ear"),
        ("halpe26", 17, "top_head"),
        ("halpe26", 19, "mid_hip"),
        ("halpe26", 21, "right_big_toe"),
        ("panoptic19", 2, "mid_hip"),
        ("panoptic19", 6, "left_hip"),
        ("panoptic19", 16, "left_ear"),
        ("panoptic19", 17, "right_eye"),
        ("coco_wholebody133", 19, "left_heel"),
        ("coco_wholebody133", 22, "right_heel"),
    ],
)
def test_native_indices(name, index, joint):
    assert SKELETONS[name].joints[index] == joint


def test_canonical_skeleton_matches_keypoints_module():
    canonical = SKELETONS["canonical23"]
    assert canonical.joints == CANONICAL_JOINTS
    assert canonical.flip_index == FLIP_INDEX
    assert SKELETONS["coco17"].joints == CANONICAL_JOINTS[:17]


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_flip_is_an_involution_swapping_sides(name):
    skel = SKELETONS[name]
    flip = skel.flip_index
    assert tuple(flip[i] for i in flip) == tuple(range(skel.num_joints))
    for i, j in enumerate(flip):
        a, b = skel.joints[i], skel.joints[j]
        if a.startswith("left_"):
            assert b == "right_" + a[len("left_") :]
    assert all(0 <= a < skel.num_joints and 0 <= b < skel.num_joints for a, b in skel.limb_index)


def test_skeleton_rejects_limbs_on_unknown_joints():
    with pytest.raises(ValueError, match="limbs name joint"):
        Skeleton("bad", ("a", "b"), (("a", "c"),), ())
    with pytest.raises(ValueError, match="unique"):
        Skeleton("bad", ("a", "a"), (), ())


def test_unknown_skeleton_lists_known_ones():
    with pytest.raises(ValueError, match="known skeletons are .*body25"):
        get_skeleton("body_25")
    with pytest.raises(ValueError, match="has no joint 'neck'"):
        SKELETONS["coco17"].index("neck")
