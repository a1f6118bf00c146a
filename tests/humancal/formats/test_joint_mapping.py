"""Skeleton <-> canonical mapping and the derived-joint rules, on hand-made points."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.formats.joint_mapping import DERIVED_JOINTS, from_canonical, to_canonical
from humancal.formats.skeletons import SKELETONS
from humancal.keypoints import CANONICAL_JOINTS, JOINT_INDEX


def _canonical_3d() -> tuple[np.ndarray, np.ndarray]:
    """A standing person, world metres, Z up: every canonical joint at a distinct point, distinct scores."""
    kp = np.zeros((23, 3))
    kp[:, 0] = np.arange(23) * 0.01  # distinct filler
    pts = {
        "nose": (0.0, 0.1, 1.6),
        "left_shoulder": (-0.2, 0.0, 1.4),
        "right_shoulder": (0.2, 0.0, 1.4),
        "left_hip": (-0.1, 0.0, 0.9),
        "right_hip": (0.1, 0.02, 0.9),
    }
    for name, p in pts.items():
        kp[JOINT_INDEX[name]] = p
    scores = 0.5 + np.arange(23) / 100.0
    return kp, scores


def test_shelf15_from_canonical_applies_the_mvpose_head_rule_in_3d():
    kp, sc = _canonical_3d()
    out, out_sc = from_canonical(kp, sc, "shelf15")
    skel = SKELETONS["shelf15"]
    neck = np.array([0.0, 0.0, 1.4])
    np.testing.assert_allclose(out[skel.index("bottom_head")], [0.0, 0.05, 1.5])  # halfway neck -> nose
    nose_offset = np.array([0.0, 0.1, 0.2])
    np.testing.assert_allclose(out[skel.index("top_head")], neck + np.array([0.75, 0.75, 1.5]) * nose_offset)
    np.testing.assert_allclose(out[skel.index("top_head")], [0.0, 0.075, 1.7])
    np.testing.assert_allclose(out[skel.index("pelvis")], [0.0, 0.01, 0.9])
    head_sources = [JOINT_INDEX[n] for n in ("nose", "left_shoulder", "right_shoulder")]
    assert out_sc[skel.index("top_head")] == pytest.approx(sc[head_sources].min())
    assert out_sc[skel.index("pelvis")] == pytest.approx(min(sc[JOINT_INDEX["left_hip"]], sc[JOINT_INDEX["right_hip"]]))
    np.testing.assert_array_equal(out[skel.index("left_wrist")], kp[JOINT_INDEX["left_wrist"]])
    assert out_sc[skel.index("left_wrist")] == sc[JOINT_INDEX["left_wrist"]]


def test_top_head_is_3d_only_and_bottom_head_works_in_2d():
    kp, sc = _canonical_3d()
    out, out_sc = from_canonical(kp[:, :2], sc, "shelf15")
    skel = SKELETONS["shelf15"]
    assert np.isnan(out[skel.index("top_head")]).all() and out_sc[skel.index("top_head")] == 0
    np.testing.assert_allclose(out[skel.index("bottom_head")], [0.0, 0.05])
    assert DERIVED_JOINTS["top_head"].dims == (3,)


def test_body25_from_canonical_derives_neck_and_mid_hip_with_min_score():
    kp, sc = _canonical_3d()
    out, out_sc = from_canonical(kp[:, :2], sc, "body25")
    skel = SKELETONS["body25"]
    np.testing.assert_allclose(out[skel.index("neck")], [0.0, 0.0])
    np.testing.assert_allclose(out[skel.index("mid_hip")], [0.0, 0.01])
    assert out_sc[skel.index("neck")] == min(sc[JOINT_INDEX["left_shoulder"]], sc[JOINT_INDEX["right_shoulder"]])
    for name in CANONICAL_JOINTS:
        np.testing.assert_array_equal(out[skel.index(name)], kp[JOINT_INDEX[name], :2])


def test_derived_joint_is_absent_when_a_source_is_absent():
    kp, sc = _canonical_3d()
    sc[JOINT_INDEX["right_shoulder"]] = 0.0
    kp[JOINT_INDEX["nose"]] = np.nan  # NaN coordinates count as absent even with a positive score
    out, out_sc = from_canonical(kp, sc, "shelf15")
    skel = SKELETONS["shelf15"]
    for name in ("bottom_head", "top_head"):
        assert np.isnan(out[skel.index(name)]).all() and out_sc[skel.index(name)] == 0
    assert out_sc[skel.index("right_shoulder")] == 0 and np.isnan(out[skel.index("right_shoulder")]).all()
    assert out_sc[skel.index("pelvis")] > 0


def test_to_canonical_picks_by_name_and_leaves_missing_joints_absent():
    body25 = SKELETONS["body25"]
    kp = np.stack([np.arange(25.0), 100 + np.arange(25.0)], axis=-1)
    sc = np.linspace(0.1, 0.9, 25)
    out, out_sc = to_canonical(kp, sc, "body25")
    for c, name in enumerate(CANONICAL_JOINTS):
        j = body25.index(name)
        np.testing.assert_array_equal(out[c], kp[j])
        assert out_sc[c] == sc[j]
    coco, coco_sc = to_canonical(kp[:17], sc[:17], "coco17")
    assert np.isnan(coco[17:]).all() and (coco_sc[17:] == 0).all()
    shelf = SKELETONS["shelf15"]
    shelf_kp = np.arange(45.0).reshape(15, 3)
    s_out, s_sc = to_canonical(shelf_kp, np.ones(15), "shelf15")
    np.testing.assert_array_equal(s_out[JOINT_INDEX["left_shoulder"]], shelf_kp[shelf.index("left_shoulder")])
    assert s_sc[JOINT_INDEX["nose"]] == 0 and np.isnan(s_out[JOINT_INDEX["nose"]]).all()


def test_zero_score_source_joint_comes_out_nan():
    kp = np.ones((17, 2))
    sc = np.ones(17)
    sc[3] = 0.0
    out, out_sc = to_canonical(kp, sc, "coco17")
    assert np.isnan(out[3]).all() and out_sc[3] == 0


@pytest.mark.parametrize("name", ["body25", "coco18", "halpe26", "panoptic19", "coco_wholebody133"])
def test_round_trip_through_a_skeleton_keeps_the_canonical_joints_it_has(name):
    rng = np.random.default_rng(1)
    kp = rng.normal(size=(2, 3, 23, 2))
    sc = rng.uniform(0.1, 1.0, size=(2, 3, 23))
    there, there_sc = from_canonical(kp, sc, name)
    back, back_sc = to_canonical(there, there_sc, name)
    has = np.array([n in SKELETONS[name].joints for n in CANONICAL_JOINTS])
    np.testing.assert_array_equal(back[..., has, :], kp[..., has, :])
    np.testing.assert_array_equal(back_sc[..., has], sc[..., has])
    assert (back_sc[..., ~has] == 0).all()


def test_shape_errors_name_expected_and_received():
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 25, 2 or 3\), got \(2, 24, 2\)"):
        to_canonical(np.zeros((2, 24, 2)), np.zeros((2, 24)), "body25")
    with pytest.raises(ValueError, match="scores of the canonical set"):
        from_canonical(np.zeros((23, 3)), np.zeros(22), "body25")
