"""Merging skeleton fragments that the PAF links left apart, by the body's geometry.

When a joint is occluded or undetected, the greedy assembly has no PAF link across it and one person falls apart
into fragments (a lone leg below a body without that hip). A fragment is merged into a host with disjoint joint
types when

* no limb joins them directly with a PAF score of (about) zero: the detector saw both candidates and found no link;
* their closest joints in the body tree have at most ``max_missing_joints`` joints between them;
* every pair of their joints obeys the triangle inequality along the body tree: the image distance of joints ``a``
  and ``b`` is at most the summed length of the bones between them times the person's image scale (pixels per
  metre, the largest bone-length ratio of either part), with a tolerance and a noise margin.

Among the hosts that pass, the one whose closest joint pair is nearest (relative to its bone path) wins.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse.csgraph import shortest_path

from humancal.config import Config, at_least, positive
from humancal.grouping.candidates import CandidateFrame

__all__ = ["BODY25_BONE_LENGTHS_M", "MergeConfig", "merge_fragments", "tree_distances_m"]

BODY25_BONE_LENGTHS_M: dict[tuple[int, int], float] = {
    (1, 8): 0.50,
    (9, 10): 0.43,
    (10, 11): 0.42,
    (8, 9): 0.11,
    (8, 12): 0.11,
    (12, 13): 0.43,
    (13, 14): 0.42,
    (1, 2): 0.19,
    (2, 3): 0.30,
    (3, 4): 0.27,
    (2, 17): 0.27,
    (1, 5): 0.19,
    (5, 6): 0.30,
    (6, 7): 0.27,
    (5, 18): 0.27,
    (1, 0): 0.22,
    (0, 15): 0.04,
    (0, 16): 0.04,
    (15, 17): 0.09,
    (16, 18): 0.09,
    (14, 19): 0.16,
    (19, 20): 0.05,
    (14, 21): 0.08,
    (11, 22): 0.16,
    (22, 23): 0.05,
    (11, 24): 0.08,
}
"""Typical adult bone lengths (metres) of the 26 BODY_25 limbs; only their ratios matter here."""


@dataclass(frozen=True)
class MergeConfig(Config):
    """Thresholds of :func:`merge_fragments`.

    Attributes:
        tolerance: allowed ratio of a joint pair's image distance to its tree length times the scale.
        margin_px: detector noise allowance added to every distance bound, pixels.
        max_fragment_joints: only people with at most this many joints are merged into another one.
        max_direct_paf: a merge is vetoed when a limb joins the two directly and its PAF score is at most this
            (the detector saw the candidates and found no link between them).
        max_missing_joints: the closest joints of the two (fewest bones apart) may have at most this many joints
            between them in the body tree; longer gaps leave the fragment's place too loosely determined.
    """

    tolerance: float = field(default=1.2, metadata=positive())
    margin_px: float = field(default=10.0, metadata=at_least(0))
    max_fragment_joints: int = field(default=12, metadata=at_least(1, integer=True))
    max_direct_paf: float = 0.0
    max_missing_joints: int = field(default=2, metadata=at_least(0, integer=True))


def tree_distances_m(num_joints: int, bone_lengths_m: dict[tuple[int, int], float]) -> tuple[np.ndarray, np.ndarray]:
    """Shortest paths between joint types over the limbs.

    Returns:
        length_m: (joint, joint) summed bone length of the shortest path, metres (inf where unconnected).
        hops: (joint, joint) number of bones on the path with the fewest bones.
    """
    graph = np.zeros((num_joints, num_joints))
    for (a, b), length in bone_lengths_m.items():
        graph[a, b] = graph[b, a] = length
    hops = shortest_path(graph > 0, method="D", directed=False, unweighted=True)
    return shortest_path(graph, method="D", directed=False), hops


def merge_fragments(
    frame: CandidateFrame,
    people: list[np.ndarray],
    tree: tuple[np.ndarray, np.ndarray],
    bone_lengths_m: dict[tuple[int, int], float],
    config: MergeConfig,
) -> list[np.ndarray]:
    """Merge joint-disjoint people whose joints are geometrically one body.

    Fragments (people with at most ``config.max_fragment_joints`` joints), smallest first, are merged into the
    host (a joint-disjoint person with at least as many joints) that passes the tests of the module docstring with
    the smallest anchor ratio (image distance of their closest joint pair over its bone path times the scale),
    until no merge is left.

    Args:
        frame: the candidates the people index into.
        people: per person (joint,) candidate index, -1 where none.
        tree: (joint, joint) tree lengths and bone counts from :func:`tree_distances_m`.
        bone_lengths_m: bone lengths used to estimate each person's image scale.
        config: thresholds.

    Returns:
        The people after merging (new arrays; the input is not modified).
    """
    people = [p.copy() for p in people]
    while True:
        order = sorted(range(len(people)), key=lambda p: int((people[p] >= 0).sum()))
        merged = False
        for f in order:
            frag = people[f]
            n_frag = int((frag >= 0).sum())
            if n_frag > config.max_fragment_joints:
                break
            best, best_ratio = -1, np.inf
            for h, host in enumerate(people):
                if h == f or int((host >= 0).sum()) < n_frag or ((host >= 0) & (frag >= 0)).any():
                    continue
                ratio = _anchor_ratio(frame, frag, host, tree, bone_lengths_m, config)
                if ratio < best_ratio:
                    best, best_ratio = h, ratio
            if best >= 0:
                people[best] = np.maximum(people[best], frag)
                del people[f]
                merged = True
                break
        if not merged:
            return people


def _positions(frame: CandidateFrame, person: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    joints = np.flatnonzero(person >= 0)
    xy = np.array([frame.xy_px[j][person[j]] for j in joints]).reshape(-1, 2)
    return joints, xy


def _scale_px_per_m(joints: np.ndarray, xy: np.ndarray, bone_lengths_m: dict[tuple[int, int], float]) -> float:
    """Largest bone image length per metre: foreshortening only shrinks bones, so this bounds the scale below."""
    where = {j: i for i, j in enumerate(joints)}
    ratios = [
        np.linalg.norm(xy[where[a]] - xy[where[b]]) / length
        for (a, b), length in bone_lengths_m.items()
        if a in where and b in where
    ]
    return max(ratios, default=0.0)


def _anchor_ratio(
    frame: CandidateFrame,
    frag: np.ndarray,
    host: np.ndarray,
    tree: tuple[np.ndarray, np.ndarray],
    bone_lengths_m: dict[tuple[int, int], float],
    config: MergeConfig,
) -> float:
    """Ratio of the closest joint pair if every pair passes the triangle test, else inf."""
    for (a, b), paf in zip(frame.limbs, frame.paf, strict=True):
        for u, w in ((frag, host), (host, frag)):
            if u[a] >= 0 and w[b] >= 0 and paf[u[a], w[b]] <= config.max_direct_paf:
                return np.inf
    tree_m, hops = tree
    jf, xf = _positions(frame, frag)
    jh, xh = _positions(frame, host)
    if hops[np.ix_(jf, jh)].min() - 1 > config.max_missing_joints:
        return np.inf
    scale = max(_scale_px_per_m(jf, xf, bone_lengths_m), _scale_px_per_m(jh, xh, bone_lengths_m))
    if scale <= 0:
        return np.inf
    dist_px = np.linalg.norm(xf[:, None] - xh[None], axis=-1)
    bound_px = config.tolerance * scale * tree_m[np.ix_(jf, jh)] + config.margin_px
    if not (dist_px <= bound_px).all():
        return np.inf
    closest = np.unravel_index(np.argmin(tree_m[np.ix_(jf, jh)]), dist_px.shape)
    return float(dist_px[closest] / (scale * tree_m[jf[closest[0]], jh[closest[1]]]))
