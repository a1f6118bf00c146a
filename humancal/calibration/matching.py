"""Cross-view groups of detections (one person in one frame) from matched detection pairs.

Pairs that agree with the consensus rotation of their views and with the linear translation solve are
joined by union-find within each frame. A group holding two detections of the same view is contradictory
(two people merged through a wrong pair). Without pair costs it is dropped: precision matters more than recall
for calibration. With pair costs (e.g. the linear solve's root distances) it is split instead: its pairs are
joined again from the cheapest up, skipping any pair that would put two detections of one view together. That
keeps the people of crowded, static scenes (seated people close together), where many wrong pairs pass the
consistency tests and nearly every component holds a conflict.

A wrong pair can still pass those tests when people stand still: a seated person matched to their neighbour in
another view, the same way in every frame, is a consistent alternative geometry that pulls the bundle
adjustment towards a wrong rig. After a bundle adjustment such a detection reprojects tens of standard deviations
away from its group's keypoints; :func:`drop_mismatched_detections` takes it out of its group.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from humancal.tables.detections import DenseDetections

__all__ = ["drop_mismatched_detections", "groups_from_pairs", "spread_groups"]


def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        parent[i], i = root, parent[i]
    return root


def groups_from_pairs(rows_a: np.ndarray, rows_b: np.ndarray, view: np.ndarray, num_rows: int,
                      pair_cost: np.ndarray | None = None) -> list[np.ndarray]:
    """Connected components of the pair graph, without view conflicts.

    Args:
        rows_a, rows_b: (M,) matched detection rows (pairs lie in one frame and in two different views).
        view: (num_rows,) view of every detection row.
        num_rows: number of detection rows D.
        pair_cost: (M,) optional cost of every pair (lower: more certainly one person); components with a view
            conflict are then split (see the module docstring) instead of dropped.

    Returns:
        Groups as arrays of detection rows (at least two views each, at most one detection per view), sorted by
        their first row.
    """
    rows_a, rows_b = np.asarray(rows_a, dtype=np.int64), np.asarray(rows_b, dtype=np.int64)
    parent = np.arange(num_rows)
    for a, b in zip(rows_a.tolist(), rows_b.tolist()):
        ra, rb = _find(parent, a), _find(parent, b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    members = np.unique(np.r_[rows_a, rows_b]).astype(np.int64)
    roots = np.array([_find(parent, int(m)) for m in members], dtype=np.int64)
    order = np.argsort(roots, kind="stable")
    members, roots = members[order], roots[order]
    splits = np.flatnonzero(np.diff(roots)) + 1
    groups, conflicted = [], []
    for g in np.split(members, splits):
        views = view[g]
        if len(g) >= 2 and len(np.unique(views)) == len(g):
            groups.append(g)
        elif len(g) > 2:
            conflicted.append(g)
    if pair_cost is not None and conflicted:
        groups += _split_conflicts(rows_a, rows_b, np.asarray(pair_cost, dtype=np.float64), view, conflicted)
    return sorted(groups, key=lambda g: int(g[0]))


def _split_conflicts(rows_a, rows_b, cost, view, conflicted) -> list[np.ndarray]:
    """Join the pairs inside conflicted components again, cheapest first, never two detections of one view."""
    inside = np.zeros(len(view), bool)
    inside[np.concatenate(conflicted)] = True
    keep = np.flatnonzero(inside[rows_a] & np.isfinite(cost))
    keep = keep[np.argsort(cost[keep], kind="stable")]
    parent = {}
    views_of = {}  # root -> bit mask of the views in its component

    def find(i):
        parent.setdefault(i, i)
        views_of.setdefault(i, 1 << int(view[i]))
        return _find_dict(parent, i)

    for a, b in zip(rows_a[keep].tolist(), rows_b[keep].tolist()):
        ra, rb = find(a), find(b)
        if ra == rb or views_of[ra] & views_of[rb]:
            continue
        low, high = min(ra, rb), max(ra, rb)
        parent[high] = low
        views_of[low] |= views_of.pop(high)
    components: dict[int, list[int]] = {}
    for i in parent:
        components.setdefault(_find_dict(parent, i), []).append(i)
    return [np.array(sorted(c), dtype=np.int64) for c in components.values() if len(c) >= 2]


def _find_dict(parent: dict, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        parent[i], i = root, parent[i]
    return root


def drop_mismatched_detections(groups: list[np.ndarray], error_sigma: np.ndarray, threshold_sigma: float,
                               max_fraction: float) -> tuple[list[np.ndarray], np.ndarray, int]:
    """Take out of their groups the detections that reproject far from their group's keypoints.

    Args:
        groups: G arrays of detection rows.
        error_sigma: (S,) per detection of the groups, in the order of ``np.concatenate(groups)``, its median
            reprojection error in units of the keypoint std (:attr:`BundleResult.detection_error_sigma
            <humancal.calibration.bundle.BundleResult.detection_error_sigma>`); NaN: no keypoint used.
        threshold_sigma: a detection above this error is dropped.
        max_fraction: when more than this fraction of the detections is above the threshold, nothing is dropped:
            the rig itself is off, not a few matches, and dropping would throw away the evidence.

    Returns:
        The remaining groups (at least two detections each), the index of each in ``groups`` (K,), and the number
        of detections dropped.
    """
    sizes = [len(g) for g in groups]
    if len(error_sigma) != sum(sizes):
        raise ValueError(f"error_sigma has {len(error_sigma)} values for {sum(sizes)} detections in the groups")
    bad = np.nan_to_num(np.asarray(error_sigma, dtype=np.float64), nan=0.0) > threshold_sigma
    if not bad.any() or bad.mean() > max_fraction:
        return list(groups), np.arange(len(groups)), 0
    kept, index = [], []
    for k, (g, flags) in enumerate(zip(groups, np.split(bad, np.cumsum(sizes)[:-1]))):
        rest = g[~flags]
        if len(rest) >= 2:
            kept.append(rest)
            index.append(k)
    return kept, np.asarray(index, dtype=int), int(bad.sum())


def spread_groups(groups: list[np.ndarray], detections: DenseDetections, max_groups: int,
                  rng: np.random.Generator) -> np.ndarray:
    """Indices (sorted) of at most ``max_groups`` of the groups (arrays of rows of ``detections``), spread evenly
    over the frames, the groups with more views first within a frame (ties broken by ``rng``)."""
    if len(groups) <= max_groups:
        return np.arange(len(groups))
    frames = np.array([detections.frame[g[0]] for g in groups])
    sizes = np.array([len(g) for g in groups])
    order = np.lexsort((rng.random(len(groups)), -sizes, frames))  # by frame, larger groups first
    return np.sort(order[np.linspace(0, len(order) - 1, max_groups).round().astype(int)])
