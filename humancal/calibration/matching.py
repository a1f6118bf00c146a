"""Cross-view groups of detections (one person in one frame) from matched detection pairs.

Pairs that agree with the consensus rotation of their views and with the linear translation solve are
joined by union-find within each frame. A group holding two detections of the same view is contradictory
(two people merged through a wrong pair) and is dropped: precision matters more than recall for calibration.
"""

from __future__ import annotations

import numpy as np

__all__ = ["groups_from_pairs"]


def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        parent[i], i = root, parent[i]
    return root


def groups_from_pairs(rows_a: np.ndarray, rows_b: np.ndarray, view: np.ndarray, num_rows: int) -> list[np.ndarray]:
    """Connected components of the pair graph, without view conflicts.

    Args:
        rows_a, rows_b: (M,) matched detection rows (pairs lie in one frame and in two different views).
        view: (num_rows,) view of every detection row.
        num_rows: number of detection rows D.

    Returns:
        Groups as arrays of detection rows (at least two views each, at most one detection per view), sorted by
        their first row.
    """
    parent = np.arange(num_rows)
    for a, b in zip(np.asarray(rows_a).tolist(), np.asarray(rows_b).tolist()):
        ra, rb = _find(parent, a), _find(parent, b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    members = np.unique(np.r_[rows_a, rows_b]).astype(np.int64)
    roots = np.array([_find(parent, int(m)) for m in members], dtype=np.int64)
    order = np.argsort(roots, kind="stable")
    members, roots = members[order], roots[order]
    splits = np.flatnonzero(np.diff(roots)) + 1
    groups = []
    for g in np.split(members, splits):
        views = view[g]
        if len(g) >= 2 and len(np.unique(views)) == len(g):
            groups.append(g)
    return groups
