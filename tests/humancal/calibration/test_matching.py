"""Cross-view groups from matched pairs: a wrong pair no longer costs the people it touches."""

import numpy as np

from humancal.calibration.matching import groups_from_pairs

# one frame, two people (A: rows 0-2, B: rows 3-5), each seen by views 0, 1 and 2
VIEW = np.array([0, 1, 2, 0, 1, 2])
RIGHT = [(0, 1), (1, 2), (0, 2), (3, 4), (4, 5), (3, 5)]


def _pairs(pairs):
    a, b = np.array(pairs).T
    return a, b


def test_a_conflict_free_component_is_a_group():
    a, b = _pairs(RIGHT)
    assert [g.tolist() for g in groups_from_pairs(a, b, VIEW, 6)] == [[0, 1, 2], [3, 4, 5]]


def test_a_wrong_pair_drops_both_people_without_costs_and_is_split_off_with_them():
    a, b = _pairs(RIGHT + [(0, 4)])  # A in view 0 wrongly matched with B in view 1: one component, view conflicts
    assert groups_from_pairs(a, b, VIEW, 6) == []
    cost = np.array([0.05] * len(RIGHT) + [0.3])
    assert [g.tolist() for g in groups_from_pairs(a, b, VIEW, 6, pair_cost=cost)] == [[0, 1, 2], [3, 4, 5]]


def test_a_split_never_puts_two_detections_of_one_view_together():
    rng = np.random.default_rng(0)
    a, b = np.triu_indices(6, 1)
    keep = VIEW[a] != VIEW[b]  # every cross-view pair, right or wrong, with random costs
    a, b = a[keep], b[keep]
    groups = groups_from_pairs(a, b, VIEW, 6, pair_cost=rng.random(len(a)))
    assert groups and all(len(np.unique(VIEW[g])) == len(g) for g in groups)
    assert sorted(np.concatenate(groups).tolist()) == list(range(6))
