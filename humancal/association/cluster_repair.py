"""Repairs of the clusters the matching found in each frame (step 3 of :func:`humancal.association.associate`).

With many views, a few of a person's detections can be left out of that person's cluster: mostly detections whose
left and right joints the detector swapped, which agree with each other as a mirrored skeleton and less with the
person's other views. :func:`merge_split_clusters` joins a person's clusters of one frame, :func:`complete_clusters`
gives a lone detection to the cluster it fits. Both compare a skeleton with a mirrored one too, and a detection with
its left and right joints swapped too; the triangulation then drops the swapped views joint by joint.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from humancal.association.cluster_triangulation import reprojection_errors_px
from humancal.keypoints import FLIP_INDEX

__all__ = ["complete_clusters", "merge_split_clusters"]

_MIN_JOINTS = 3
"""Joints two skeletons, or a skeleton and a detection, must share to be compared."""


def _pair_distance(joints: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P,) median joint distance of skeletons ``a`` and ``b`` over the joints both know (inf below
    ``_MIN_JOINTS``), the smaller of ``b`` as it is and ``b`` mirrored left to right, metres."""
    out = np.full(len(a), np.inf)
    for other in (joints[b], joints[b][:, list(FLIP_INDEX)]):
        d = np.linalg.norm(joints[a] - other, axis=-1)  # (P, 23), NaN where either misses the joint
        enough = np.isfinite(d).sum(-1) >= _MIN_JOINTS
        if enough.any():
            out[enough] = np.minimum(out[enough], np.nanmedian(d[enough], axis=-1))
    return out


def _near_cluster_pairs(cluster_frame: np.ndarray, joints: np.ndarray, distance_m: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs ``a < b`` of clusters of one frame whose skeletons lie within ``distance_m`` of each other, and
    their distances (:func:`_pair_distance`), all frames at once (``cluster_frame`` is sorted)."""
    a_all, b_all = [], []
    for k in range(1, len(cluster_frame)):
        same = np.flatnonzero(cluster_frame[:-k] == cluster_frame[k:])
        if len(same) == 0:
            break
        a_all.append(same)
        b_all.append(same + k)
    if not a_all:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    a, b = np.concatenate(a_all), np.concatenate(b_all)
    distance = _pair_distance(joints, a, b)
    near = distance < distance_m
    return a[near], b[near], distance[near]


def merge_split_clusters(matchings: list, frame_start: np.ndarray, cluster: np.ndarray, cluster_frame: np.ndarray,
                         joints: np.ndarray, view: np.ndarray, keypoints_px: np.ndarray, scores: np.ndarray,
                         cameras: list, *, distance_m: float, threshold_px: float) -> int:
    """Merge the clusters of a frame that are one person split in two; ``matchings`` is updated in place.

    With many views, a few of a person's detections can end up in a cluster of their own, which then starts a
    track of its own: mostly detections whose left and right joints were swapped by the detector in two or three
    views (such detections agree with each other, as a mirrored skeleton, and less with the rest). Two clusters of
    one frame without a common view are merged when their triangulated skeletons lie together (median joint
    distance below ``distance_m``, one of them mirrored left to right or not) and the larger one's skeleton
    reprojects onto every detection of the smaller one (median over the joints both have within
    ``threshold_px``, the detection's joints swapped left to right or not): two people cannot share
    their place, and one standing behind another in a view fails the 3D test. The triangulation then drops the
    swapped views joint by joint, as it does for any left-right flip.

    Args:
        matchings: per frame the :class:`FrameMatching` (``cluster`` relabelled where clusters merge).
        frame_start: (F + 1,) detection rows of frame index ``i`` are ``frame_start[i]:frame_start[i + 1]``.
        cluster: (D,) global cluster of every detection or -1; cluster_frame: (C,) frame index of every cluster.
        joints: (C, 23, 3) triangulated skeletons (NaN where unknown), metres.
        view: (D,) view of every detection; keypoints_px: (D, 23, 2) undistorted pixels; scores: (D, 23).
        cameras: the V pinhole cameras of ``keypoints_px``.
        distance_m: the skeletons' largest median joint distance, metres
            (``TrackingConfig.merge_distance_m``).
        threshold_px: the largest median reprojection error, pixels (``TrackingConfig.outlier_threshold_px``).

    Returns:
        The number of merges.
    """
    merges = 0
    bounds = np.searchsorted(cluster_frame, np.arange(len(matchings) + 1))
    near_a, near_b, near_distance = _near_cluster_pairs(cluster_frame, joints, distance_m)
    for i in np.unique(cluster_frame[near_a]):
        first = bounds[i]
        ids = np.arange(first, bounds[i + 1])
        local = cluster[frame_start[i]:frame_start[i + 1]] - first  # local cluster of each row, < 0: none
        rows = np.arange(frame_start[i], frame_start[i + 1])
        members = [rows[local == k] for k in range(len(ids))]
        here = cluster_frame[near_a] == i
        a, b = near_a[here] - first, near_b[here] - first
        root = np.arange(len(ids))
        group_views = [set(view[m].tolist()) for m in members]
        for k in np.argsort(near_distance[here], kind="stable"):
            ra, rb = root[a[k]], root[b[k]]
            if ra == rb or group_views[ra] & group_views[rb]:
                continue
            big, small = (ra, rb) if len(group_views[ra]) >= len(group_views[rb]) else (rb, ra)
            if not _reprojects_onto(joints[first + big], np.flatnonzero(root == small), members, view,
                                    keypoints_px, scores, cameras, threshold_px):
                continue
            root[root == small] = big
            group_views[big] |= group_views[small]
            merges += 1
        if (root != np.arange(len(ids))).any():
            merged = np.where(local >= 0, root[np.maximum(local, 0)], -1)
            # relabel 0..C'-1 in the order of each cluster's first detection, as the matching numbers them
            _, first_row = np.unique(merged[merged >= 0], return_index=True)
            order = np.unique(merged[merged >= 0])[np.argsort(first_row)]
            relabel = np.full(len(ids), -1, np.int64)
            relabel[order] = np.arange(len(order))
            matchings[i] = replace(matchings[i], cluster=np.where(merged >= 0, relabel[np.maximum(merged, 0)], -1))
    return merges


def _reprojects_onto(skeleton: np.ndarray, clusters: np.ndarray, members: list, view: np.ndarray,
                     keypoints_px: np.ndarray, scores: np.ndarray, cameras: list, threshold_px: float) -> bool:
    """Whether a (23, 3) skeleton reprojects onto every detection of the given clusters of a frame within
    ``threshold_px`` (:func:`_reprojection_median_px`)."""
    return all(_reprojection_median_px(skeleton, d, view, keypoints_px, scores, cameras) < threshold_px
               for d in np.concatenate([members[k] for k in clusters]))


def _reprojection_median_px(skeleton: np.ndarray, d: int, view: np.ndarray, keypoints_px: np.ndarray,
                            scores: np.ndarray, cameras: list) -> float:
    """Median reprojection error of a (23, 3) skeleton onto detection ``d`` over the joints both have (at least
    ``_MIN_JOINTS``; inf otherwise), the detection's left and right joints as they are or swapped, whichever is
    smaller, pixels."""
    best = np.inf
    flip = list(FLIP_INDEX)
    for points, weights in ((keypoints_px[d], scores[d]), (keypoints_px[d][flip], scores[d][flip])):
        seen = np.isfinite(skeleton).all(-1) & (weights > 0) & np.isfinite(points).all(-1)
        if seen.sum() >= _MIN_JOINTS:
            errors, _ = reprojection_errors_px([cameras[view[d]]], skeleton[seen], points[None, seen])
            best = min(best, float(np.median(errors[0])))
    return best


def complete_clusters(matchings: list, frame_start: np.ndarray, cluster: np.ndarray, cluster_frame: np.ndarray,
                      joints: np.ndarray, view: np.ndarray, keypoints_px: np.ndarray, scores: np.ndarray,
                      cameras: list, *, threshold_px: float) -> np.ndarray:
    """Give a detection that no cluster took to the one cluster of its frame that lacks its view and whose skeleton
    reprojects onto it within ``threshold_px`` (:func:`_reprojection_median_px`; left and right swapped or not);
    left alone when no cluster or several do. ``matchings`` is updated in place (arguments as
    :func:`merge_split_clusters`).

    A detection with left and right swapped agrees with the other views less than its person's detections do,
    and the matching can leave it out; the triangulation drops its swapped joints as it does for any flip.

    Returns:
        The global clusters that grew, sorted.
    """
    grown: set[int] = set()
    bounds = np.searchsorted(cluster_frame, np.arange(len(matchings) + 1))
    for i in np.flatnonzero(np.diff(bounds) >= 1):
        local = matchings[i].cluster
        lone = np.flatnonzero(local < 0)
        if len(lone) == 0:
            continue
        rows = np.arange(frame_start[i], frame_start[i + 1])
        ids = np.arange(bounds[i], bounds[i + 1])
        taken = [set(view[rows[local == k]].tolist()) for k in range(len(ids))]
        new = local.copy()
        for j in lone:
            d = rows[j]
            fits = [k for k in range(len(ids)) if view[d] not in taken[k] and _reprojection_median_px(
                joints[ids[k]], d, view, keypoints_px, scores, cameras) < threshold_px]
            if len(fits) == 1:
                new[j] = fits[0]
                taken[fits[0]].add(int(view[d]))
                grown.add(int(ids[fits[0]]))
        if (new != local).any():
            matchings[i] = replace(matchings[i], cluster=new)
    return np.array(sorted(grown), np.int64)
