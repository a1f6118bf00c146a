"""Bottom-up PAF grouping on synthetic candidates: assembly, fragment repair, canonical table."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.grouping import (
    BODY25_JOINTS,
    BODY25_LIMBS,
    CandidateFrame,
    GroupingConfig,
    MergeConfig,
    group_detections,
    group_frame,
    people_to_detections,
)
from humancal.grouping.merge import BODY25_BONE_LENGTHS_M, tree_distances_m
from humancal.keypoints import CANONICAL_JOINTS
from humancal.tables.schemas import validate_table

# A standing person facing the camera, metres, x right, y down, neck at the origin (BODY_25 order).
_TEMPLATE_M = np.array(
    [
        (0.00, -0.22), (0.00, 0.00), (-0.19, 0.00), (-0.22, 0.30), (-0.24, 0.56), (0.19, 0.00), (0.22, 0.30),
        (0.24, 0.56), (0.00, 0.50), (-0.11, 0.50), (-0.12, 0.93), (-0.12, 1.35), (0.11, 0.50), (0.12, 0.93),
        (0.12, 1.35), (-0.03, -0.25), (0.03, -0.25), (-0.08, -0.23), (0.08, -0.23), (0.16, 1.45), (0.20, 1.44),
        (0.11, 1.40), (-0.16, 1.45), (-0.20, 1.44), (-0.11, 1.40),
    ]
)  # fmt: skip

_J = {name: i for i, name in enumerate(BODY25_JOINTS)}


def _person(neck_px: tuple[float, float], scale_px_per_m: float = 300.0) -> np.ndarray:
    return np.asarray(neck_px, dtype=float) + scale_px_per_m * _TEMPLATE_M


def _frame(
    people: list[np.ndarray],
    rng: np.random.Generator,
    paf_same: float = 0.9,
    paf_cross: float = 0.0,
) -> tuple[CandidateFrame, list[dict[int, int]]]:
    """Candidates of the given people (NaN rows = undetected), shuffled per joint, and PAF scores: ``paf_same``
    between candidates of one person, ``paf_cross`` between people.

    Returns the frame and, per person, {joint: candidate index}.
    """
    owner: list[list[int]] = []
    xy, score, where = [], [], [dict() for _ in people]
    for j in range(len(BODY25_JOINTS)):
        present = [p for p, person in enumerate(people) if np.isfinite(person[j]).all()]
        order = rng.permutation(len(present))
        owners = [present[k] for k in order]
        for c, p in enumerate(owners):
            where[p][j] = c
        owner.append(owners)
        xy.append(np.array([people[p][j] for p in owners]).reshape(-1, 2))
        score.append(rng.uniform(0.6, 0.95, len(owners)))
    paf = []
    for a, b in BODY25_LIMBS:
        same = np.equal.outer(owner[a], owner[b]).reshape(len(owner[a]), len(owner[b]))
        paf.append(np.where(same, paf_same, paf_cross))
    return CandidateFrame(tuple(xy), tuple(score), tuple(paf), BODY25_LIMBS), where


def _as_sets(grouped) -> list[frozenset]:
    return [
        frozenset((j, int(c)) for j, c in enumerate(row) if c >= 0) for row in grouped.candidate_index
    ]


def _truth_sets(where: list[dict[int, int]]) -> list[frozenset]:
    return [frozenset(w.items()) for w in where]


def test_two_separated_people_are_recovered_exactly():
    rng = np.random.default_rng(0)
    people = [_person((200.0, 150.0)), _person((700.0, 170.0), 280.0)]
    frame, where = _frame(people, rng)
    grouped = group_frame(frame)
    assert grouped.num_people == 2
    assert sorted(_as_sets(grouped), key=len) == sorted(_truth_sets(where), key=len)
    assert (grouped.candidate_index >= 0).all()
    # Each person's pixels are one template's: no joint of the other person slipped in.
    for row in grouped.xy_px:
        matches = [np.allclose(row, person) for person in people]
        assert sum(matches) == 1


def test_cross_person_links_weaker_than_own_links_do_not_mix_people():
    rng = np.random.default_rng(1)
    people = [_person((300.0, 150.0)), _person((420.0, 160.0))]
    frame, where = _frame(people, rng, paf_same=0.9, paf_cross=0.4)
    grouped = group_frame(frame)
    assert sorted(_as_sets(grouped), key=sorted) == sorted(_truth_sets(where), key=sorted)


def test_candidate_used_once_per_limb():
    # Two wrists both linked to the one elbow: only the stronger link is taken.
    rng = np.random.default_rng(2)
    person = _person((300.0, 150.0))
    decoy = np.full_like(person, np.nan)
    decoy[_J["right_wrist"]] = person[_J["right_wrist"]] + (30.0, 5.0)
    frame, where = _frame([person, decoy], rng)
    k = BODY25_LIMBS.index((3, 4))
    frame.paf[k][where[0][3], where[1][4]] = 0.5  # elbow of person 0 to the decoy wrist
    grouped = group_frame(frame, GroupingConfig(min_joints=2))
    assert grouped.num_people == 1
    assert grouped.candidate_index[0, _J["right_wrist"]] == where[0][_J["right_wrist"]]


def test_leg_fragment_without_hip_is_merged_back():
    rng = np.random.default_rng(3)
    person = _person((400.0, 120.0))
    person[_J["right_hip"]] = np.nan  # occluded hip: no PAF path from the body to the right leg
    frame, where = _frame([person, _person((850.0, 130.0))], rng)
    plain = group_frame(frame, GroupingConfig(reattach=False, merge=None))
    assert plain.num_people == 3  # body, lone right leg, second person
    grouped = group_frame(frame)
    assert grouped.num_people == 2
    assert sorted(_as_sets(grouped), key=sorted) == sorted(_truth_sets(where), key=sorted)


def test_far_fragment_is_not_merged():
    # The same right leg 600 px away from the body it lacks is not a part of it (triangle inequality fails).
    rng = np.random.default_rng(4)
    body = _person((300.0, 120.0))
    body[[_J["right_hip"], _J["right_knee"], _J["right_ankle"]]] = np.nan
    body[[_J["right_big_toe"], _J["right_small_toe"], _J["right_heel"]]] = np.nan
    leg = np.full_like(body, np.nan)
    for name in ("right_knee", "right_ankle", "right_big_toe", "right_small_toe", "right_heel"):
        leg[_J[name]] = _person((900.0, 120.0))[_J[name]]
    frame, _ = _frame([body, leg], rng)
    assert group_frame(frame).num_people == 2


def test_fragment_directly_linked_with_zero_paf_is_not_merged():
    # The detector saw the body's knee and this ankle and found no link between them: no merge.
    rng = np.random.default_rng(5)
    body = _person((300.0, 120.0))
    for name in ("right_ankle", "right_big_toe", "right_small_toe", "right_heel"):
        body[_J[name]] = np.nan
    foot = np.full_like(body, np.nan)
    for name in ("right_ankle", "right_big_toe", "right_small_toe", "right_heel"):
        foot[_J[name]] = _person((300.0, 120.0))[_J[name]] + (15.0, 0.0)
    frame, _ = _frame([body, foot], rng)
    assert group_frame(frame).num_people == 2
    assert group_frame(frame, GroupingConfig(merge=MergeConfig(max_direct_paf=-1.0))).num_people == 1


def test_spurious_knee_branch_is_replaced_by_the_full_leg():
    # The hip links more strongly to a spurious knee peak (no ankle below it) than to the true knee, whose ankle
    # and foot then form a fragment; re-attaching swaps the branches.
    rng = np.random.default_rng(6)
    person = _person((400.0, 120.0))
    spurious = np.full_like(person, np.nan)
    spurious[_J["left_knee"]] = person[_J["left_hip"]] + (5.0, 60.0)
    frame, where = _frame([person, spurious], rng)
    k = BODY25_LIMBS.index((12, 13))
    frame.paf[k][where[0][12], where[1][13]] = 0.95  # hip -> spurious knee beats hip -> true knee (0.9)
    plain = group_frame(frame, GroupingConfig(reattach=False, merge=None))
    assert plain.candidate_index[0, _J["left_knee"]] == where[1][_J["left_knee"]]
    grouped = group_frame(frame, GroupingConfig(merge=None))
    assert grouped.num_people == 1
    assert _as_sets(grouped) == [_truth_sets(where)[0]]


def test_small_and_weak_people_are_dropped():
    rng = np.random.default_rng(7)
    person = _person((400.0, 120.0))
    pair = np.full_like(person, np.nan)
    pair[[_J["left_elbow"], _J["left_wrist"]]] = _person((900.0, 100.0))[[_J["left_elbow"], _J["left_wrist"]]]
    frame, _ = _frame([person, pair], rng)
    assert group_frame(frame).num_people == 1
    assert group_frame(frame, GroupingConfig(min_joints=2, merge=None)).num_people == 2
    assert group_frame(frame, GroupingConfig(min_mean_score=0.99)).num_people == 0


def test_empty_frame_gives_no_people():
    empty = CandidateFrame(
        tuple(np.zeros((0, 2)) for _ in BODY25_JOINTS),
        tuple(np.zeros(0) for _ in BODY25_JOINTS),
        tuple(np.zeros((0, 0)) for _ in BODY25_LIMBS),
        BODY25_LIMBS,
    )
    grouped = group_frame(empty)
    assert grouped.num_people == 0
    assert grouped.xy_px.shape == (0, 25, 2)


def test_detections_table_is_canonical():
    rng = np.random.default_rng(8)
    people = [_person((200.0, 150.0)), _person((700.0, 170.0))]
    frame, _ = _frame(people, rng)
    frame.score[_J["nose"]][0] = 1.03  # OpenPose peaks can exceed 1: clipped in the table
    table = group_detections([(4, 2, frame), (5, 2, frame)], "demo")
    validate_table(table, "detections")
    assert set(table["joint"]) == set(CANONICAL_JOINTS)  # neck and mid-hip are not canonical
    assert len(table) == 2 * 2 * len(CANONICAL_JOINTS)
    assert table["score"].max() == 1.0
    assert table[["frame", "view"]].drop_duplicates().values.tolist() == [[4, 2], [5, 2]]
    grouped = group_frame(frame)
    row = table[(table.frame == 4) & (table.det_id == 0) & (table.joint == "left_big_toe")].iloc[0]
    np.testing.assert_allclose([row.x_px, row.y_px], grouped.xy_px[0, _J["left_big_toe"]])


def test_detections_table_of_nothing_is_empty():
    assert len(people_to_detections([], "demo")) == 0


def test_candidate_frame_rejects_inconsistent_input():
    xy = tuple(np.zeros((1, 2)) for _ in BODY25_JOINTS)
    score = tuple(np.ones(1) for _ in BODY25_JOINTS)
    paf = tuple(np.ones((1, 1)) for _ in BODY25_LIMBS)
    CandidateFrame(xy, score, paf, BODY25_LIMBS)
    with pytest.raises(ValueError, match=r"limb 3 \(8, 9\) PAF matrix has shape \(1, 2\), expected \(1, 1\)"):
        CandidateFrame(xy, score, paf[:3] + (np.ones((1, 2)),) + paf[4:], BODY25_LIMBS)
    with pytest.raises(ValueError, match="joint 2 has non-finite"):
        CandidateFrame(xy[:2] + (np.full((1, 2), np.nan),) + xy[3:], score, paf, BODY25_LIMBS)
    with pytest.raises(ValueError, match="joint 0 has 1 positions but 2 scores"):
        CandidateFrame(xy, (np.ones(2),) + score[1:], paf, BODY25_LIMBS)


def test_config_validation():
    with pytest.raises(ValueError, match="min_paf_score"):
        GroupingConfig(min_paf_score=1.5)
    with pytest.raises(ValueError, match="min_joints"):
        GroupingConfig(min_joints=0)
    with pytest.raises(ValueError, match="MergeConfig"):
        MergeConfig(tolerance=0.0)


def test_repair_needs_body25_limbs():
    limbs = ((0, 1),)
    frame = CandidateFrame((np.zeros((1, 2)), np.ones((1, 2))), (np.ones(1), np.ones(1)), (np.ones((1, 1)),), limbs)
    with pytest.raises(ValueError, match="BODY_25"):
        group_frame(frame)
    plain = group_frame(frame, GroupingConfig(reattach=False, merge=None, min_joints=2))
    assert plain.num_people == 1


def test_tree_distances_follow_the_bones():
    length_m, hops = tree_distances_m(25, BODY25_BONE_LENGTHS_M)
    assert hops[_J["left_ankle"], _J["left_hip"]] == 2
    np.testing.assert_allclose(length_m[_J["left_ankle"], _J["left_hip"]], 0.42 + 0.43)
    np.testing.assert_allclose(length_m[_J["neck"], _J["right_knee"]], 0.50 + 0.11 + 0.43)
