"""Bottom-up grouping of joint candidates into people by part-affinity scores (OpenPose's greedy assembly, then
fragment repair)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from humancal.config import Config, at_least, in_range
from humancal.grouping.body25 import BODY25_JOINTS, BODY25_LIMBS, BODY25_ROOT, BODY25_TREE_LIMBS
from humancal.grouping.candidates import CandidateFrame
from humancal.grouping.merge import BODY25_BONE_LENGTHS_M, MergeConfig, merge_fragments, tree_distances_m
from humancal.grouping.reattach import Tree, reattach_fragments

__all__ = ["GroupingConfig", "GroupedPeople", "group_frame"]


@dataclass(frozen=True)
class GroupingConfig(Config):
    """Settings of :func:`group_frame` (the defaults are those tuned on Shelf, ``docs/shelf.md``).

    Attributes:
        min_paf_score: a candidate pair is a limb only when its PAF score exceeds this.
        min_joints: people with fewer joints (of all types, after repair) are dropped.
        min_mean_score: people whose mean candidate score is below this are dropped.
        reattach: re-attach fragments in place of weaker branches (:mod:`humancal.grouping.reattach`).
        merge: how joint-disjoint fragments are merged (:mod:`humancal.grouping.merge`); ``None``: not at all.
    """

    min_paf_score: float = field(default=0.05, metadata=in_range(0, 1, high_open=True))
    min_joints: int = field(default=3, metadata=at_least(1, integer=True))
    min_mean_score: float = field(default=0.2, metadata=in_range(0, 1))
    reattach: bool = True
    merge: MergeConfig | None = MergeConfig()


@dataclass(frozen=True)
class GroupedPeople:
    """People assembled from the candidates of one image.

    Attributes:
        candidate_index: (person, joint) index of the candidate chosen for each joint type, -1 where none.
        xy_px: (person, joint, 2) joint positions, pixels; NaN where none.
        score: (person, joint) candidate scores; 0 where none.
    """

    candidate_index: np.ndarray
    xy_px: np.ndarray
    score: np.ndarray

    @property
    def num_people(self) -> int:
        """Number of people."""
        return int(self.candidate_index.shape[0])


def group_frame(frame: CandidateFrame, config: GroupingConfig | None = None) -> GroupedPeople:
    """Assemble the people of one image from its joint candidates and PAF scores.

    1. Greedy assembly (OpenPose's): limb by limb in ``frame.limbs`` order, candidate pairs above
       ``min_paf_score`` are taken by decreasing PAF score, each candidate at most once per limb. A pair extends
       the person holding one of its ends, joins the two people holding its ends when they share no joint type,
       or starts a new person.
    2. Re-attach (``config.reattach``): a fragment replaces a weaker branch of a person when the person's parent
       joint has a PAF link to the fragment's root too.
    3. Merge (``config.merge``): joint-disjoint fragments that are geometrically one body are joined.
    4. People with fewer than ``min_joints`` joints or a mean candidate score below ``min_mean_score`` are dropped.

    Steps 2 and 3 know the BODY_25 tree and bone lengths only.

    Args:
        frame: candidates and PAF scores of one image.
        config: settings; defaults to :class:`GroupingConfig`.

    Returns:
        The people, by decreasing total candidate score.

    Raises:
        ValueError: re-attaching or merging is asked for limbs other than :data:`BODY25_LIMBS`.
    """
    config = config or GroupingConfig()
    if (config.reattach or config.merge is not None) and frame.limbs != BODY25_LIMBS:
        raise ValueError(
            "re-attaching and merging fragments know the BODY_25 limb tree and bone lengths only; "
            "set GroupingConfig(reattach=False, merge=None) for other limb sets"
        )
    people = _assemble(frame, config.min_paf_score)
    if config.reattach and len(people) > 1:
        people = reattach_fragments(frame, people, _BODY25_TREE, config.min_paf_score, _MAJOR_JOINTS)
    if config.merge is not None and len(people) > 1:
        people = merge_fragments(frame, people, _BODY25_DISTANCES, BODY25_BONE_LENGTHS_M, config.merge)
    return _finish(frame, people, config)


def _assemble(frame: CandidateFrame, min_paf_score: float) -> list[np.ndarray]:
    """Greedy PAF assembly: per person a (joint,) array of candidate indices, -1 where none."""
    people: list[np.ndarray] = []
    for (a, b), paf in zip(frame.limbs, frame.paf, strict=True):
        for i, j, _ in _greedy_pairs(paf, min_paf_score):
            holders = [p for p, person in enumerate(people) if person[a] == i or person[b] == j]
            if len(holders) == 1:
                person = people[holders[0]]
                if person[a] < 0:
                    person[a] = i
                if person[b] < 0:
                    person[b] = j
            elif len(holders) == 2:
                p, q = holders
                if not ((people[p] >= 0) & (people[q] >= 0)).any():
                    people[p] = np.maximum(people[p], people[q])
                    del people[q]
            else:
                person = np.full(frame.num_joints, -1)
                person[a], person[b] = i, j
                people.append(person)
    return people


_MAJOR_JOINTS = np.array([not name.endswith(("eye", "ear", "toe", "heel")) for name in BODY25_JOINTS])
"""BODY_25 trunk and limb joints (nose included; eyes, ears and foot points not)."""

_BODY25_TREE = Tree(len(BODY25_JOINTS), BODY25_TREE_LIMBS, BODY25_ROOT)
_BODY25_DISTANCES = tree_distances_m(len(BODY25_JOINTS), BODY25_BONE_LENGTHS_M)


def _greedy_pairs(paf: np.ndarray, min_score: float) -> list[tuple[int, int, float]]:
    """Candidate pairs of one limb by decreasing PAF score (ties in row-major order), each candidate used once."""
    # PAF matrices are a few candidates square: plain Python beats numpy's per-call overhead here.
    ranked = sorted(
        ((s, i, j) for i, row in enumerate(paf.tolist()) for j, s in enumerate(row) if s > min_score),
        key=lambda t: -t[0],
    )
    used_a, used_b, out = set(), set(), []
    for s, i, j in ranked:
        if i in used_a or j in used_b:
            continue
        used_a.add(i)
        used_b.add(j)
        out.append((i, j, s))
    return out


def _finish(frame: CandidateFrame, people: list[np.ndarray], config: GroupingConfig) -> GroupedPeople:
    num_joints = frame.num_joints
    index = np.array(people, dtype=np.int64).reshape(-1, num_joints)
    counts = np.array(frame.num_candidates)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    flat_xy = np.concatenate([np.zeros((1, 2)), *frame.xy_px])  # row 0: placeholder for absent joints
    flat_score = np.concatenate([[0.0], *frame.score])
    has = index >= 0
    flat = np.where(has, 1 + offsets[None, :] + index, 0)
    xy = np.where(has[..., None], flat_xy[flat], np.nan)
    score = np.where(has, flat_score[flat], 0.0)
    count = has.sum(1)
    mean = score.sum(1) / np.maximum(count, 1)
    keep = (count >= config.min_joints) & (mean >= config.min_mean_score)
    order = np.argsort(-score[keep].sum(1), kind="stable")
    return GroupedPeople(index[keep][order], xy[keep][order], score[keep][order])
