"""The people of every frame as the matching found them, triangulated and repaired (step 3 of
:func:`humancal.association.associate`).

The clusters of every frame's :class:`~humancal.association.cycle_matching.FrameMatching` are numbered globally and
triangulated all at once (:mod:`~humancal.association.cluster_triangulation`); then two clusters of one frame that
are one person split in two are merged, and a detection no cluster took joins the one cluster it fits
(:mod:`~humancal.association.cluster_repair`), each step triangulating again what it changed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from humancal.association.cluster_repair import complete_clusters, merge_split_clusters
from humancal.association.cluster_triangulation import triangulate_clusters, undistorted_keypoints_px
from humancal.association.cycle_matching import FrameMatching
from humancal.association.tracking_config import TrackingConfig
from humancal.camera import CameraRig, pinhole
from humancal.tables.detections import DenseDetections

__all__ = ["MatchedClusters", "TriangulationInputs", "global_clusters", "triangulate_matchings"]


@dataclass(frozen=True)
class TriangulationInputs:
    """The (frame-sorted) detections as the triangulation reads them.

    Attributes:
        view: (D,) int64 view of every detection.
        keypoints_px: (D, 23, 2) keypoints with the lens distortion undone, pixels (NaN where missing).
        scores: (D, 23) confidences, 0 where a keypoint is missing.
        cameras: the V cameras as pinholes (no distortion).
    """

    view: np.ndarray
    keypoints_px: np.ndarray
    scores: np.ndarray
    cameras: CameraRig

    @classmethod
    def of(cls, detections: DenseDetections, rig: CameraRig) -> TriangulationInputs:
        """The inputs of ``detections`` (sorted by frame) seen by ``rig``: distortion undone, pinhole cameras."""
        keypoints = undistorted_keypoints_px(detections, rig)
        return cls(view=detections.view, keypoints_px=keypoints,
                   scores=np.where(np.isfinite(keypoints).all(-1), detections.scores, 0.0),
                   cameras=CameraRig.of([pinhole(camera) for camera in rig]))


@dataclass(frozen=True)
class MatchedClusters:
    """The clusters (one person in one frame) of all frames and their triangulated skeletons.

    Attributes:
        cluster: (D,) int64 global cluster of every (frame-sorted) detection, or -1.
        frame: (C,) int64 frame of every cluster (sorted).
        joints_world_m: (C, 23, 3) triangulated canonical joints, world frame, metres (NaN where missing).
        joint_views: (C, 23) int64 views each joint was triangulated from.
        num_views: (C,) int64 detections (views) in every cluster.
    """

    cluster: np.ndarray
    frame: np.ndarray
    joints_world_m: np.ndarray
    joint_views: np.ndarray
    num_views: np.ndarray


def global_clusters(matchings: Sequence[FrameMatching], frame_start: np.ndarray, D: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(D,) global cluster of every (sorted) detection or -1, and (C,) frame index of every cluster."""
    cluster = np.full(D, -1, np.int64)
    frame_of = []
    offset = 0
    for i, m in enumerate(matchings):
        c = m.cluster
        cluster[frame_start[i]:frame_start[i + 1]] = np.where(c >= 0, c + offset, -1)
        k = int(c.max()) + 1 if len(c) and c.max() >= 0 else 0
        frame_of.extend([i] * k)
        offset += k
    return cluster, np.asarray(frame_of, np.int64)


def triangulate_matchings(matchings: list[FrameMatching], frame_start: np.ndarray, frames: np.ndarray,
                          inputs: TriangulationInputs, config: TrackingConfig) -> MatchedClusters:
    """Triangulate every cluster; merge the clusters that are one person split in two and give the lone
    detections to the cluster they fit (``matchings`` updated in place), triangulating again after each step that
    changed something.

    Args:
        matchings: per frame index the :class:`FrameMatching` of its detections.
        frame_start: (F + 1,) detection rows of frame index ``i`` are ``frame_start[i]:frame_start[i + 1]``.
        frames: (F,) the frame of every frame index.
        inputs: the detections' undistorted keypoints, scores and views, and the cameras.
        config: ``outlier_threshold_px``, ``merge_distance_m`` and ``complete_clusters``.
    """
    cluster, cluster_frame, joints, used = _triangulate_all(matchings, frame_start, inputs, config)
    if config.merge_distance_m > 0 and merge_split_clusters(
            matchings, frame_start, cluster, cluster_frame, joints, inputs.view, inputs.keypoints_px, inputs.scores,
            inputs.cameras, distance_m=config.merge_distance_m, threshold_px=config.outlier_threshold_px):
        cluster, cluster_frame, joints, used = _triangulate_all(matchings, frame_start, inputs, config)  # renumbered
    if config.complete_clusters:
        grown = complete_clusters(matchings, frame_start, cluster, cluster_frame, joints, inputs.view,
                                  inputs.keypoints_px, inputs.scores, inputs.cameras,
                                  threshold_px=config.outlier_threshold_px)
        if len(grown):  # the numbering is kept: only the clusters that grew are triangulated again
            cluster, _ = global_clusters(matchings, frame_start, len(inputs.view))
            rows = np.flatnonzero(np.isin(cluster, grown))
            sub = np.searchsorted(grown, cluster[rows])
            joints[grown], used[grown] = triangulate_clusters(
                sub, len(grown), inputs.view[rows], inputs.keypoints_px[rows], inputs.scores[rows], inputs.cameras,
                config.outlier_threshold_px)
    views_per_cluster = np.bincount(cluster[cluster >= 0], minlength=len(cluster_frame))
    return MatchedClusters(cluster, frames[cluster_frame], joints, used, views_per_cluster)


def _triangulate_all(matchings: list[FrameMatching], frame_start: np.ndarray, inputs: TriangulationInputs,
                     config: TrackingConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(D,) global cluster of every detection or -1, (C,) frame index of every cluster, and the clusters' (C, 23, 3)
    triangulated joints (world metres) and (C, 23) views per joint."""
    cluster, cluster_frame = global_clusters(matchings, frame_start, len(inputs.view))
    joints, used = triangulate_clusters(cluster, len(cluster_frame), inputs.view, inputs.keypoints_px, inputs.scores,
                                        inputs.cameras, config.outlier_threshold_px)
    return cluster, cluster_frame, joints, used
