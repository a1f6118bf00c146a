"""Cross-view groups found again once the cameras are known.

The first groups of the calibration (:mod:`.matching`) come from lifted poses that agree after a rotation: before
any camera is known, that is all there is to match people by. It is a strict test. In a short capture it can leave
out half of the detections (two people walking side by side in 20 frames: one of them in no group), and those
missing frames are what a short capture has least of.

With the bundle-adjusted cameras the detections can be matched by geometry: the association of the method
(:func:`humancal.association.associate`, rays and poses, cycle-consistent matching, triangulation) finds every
person of every frame. Its clusters become the groups of a second bundle adjustment, each starting at its
triangulated joints. Only the clusters are used (one person in one frame, at least two views); who is who across
frames does not matter here, so the association's tracking is run without its temporal refinements and keeps every
track.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from humancal.association import SmoothingConfig, TrackingConfig, associate
from humancal.camera import CameraRig
from humancal.keypoints import NUM_JOINTS
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = ["Regrouping", "regroup_with_cameras"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Regrouping:
    """Groups of :func:`regroup_with_cameras`.

    Attributes:
        groups: G arrays of detection rows (rows of the calibration's detections), one person in one frame, one
            detection per view, at least two views; only detections with a lifted pose (``lifted.valid``).
        points_world_m: (G, 23, 3) their triangulated keypoints in the cameras' world frame, metres (NaN where a
            joint could not be triangulated).
        frames_used: frames that were matched (all, or an even spread of ``max_frames``).
    """

    groups: list[np.ndarray]
    points_world_m: np.ndarray
    frames_used: int

    @property
    def detections(self) -> int:
        """Detections in the groups."""
        return int(sum(len(g) for g in self.groups))


def regroup_with_cameras(detections: DenseDetections, lifted: LiftedPoses, cameras: CameraRig,
                         max_frames: int = 150) -> Regrouping:
    """Match the detections across views with known cameras; one group per person and frame.

    Args:
        detections: D detections of one sequence.
        lifted: their lifted poses (row-aligned; crop or camera frames).
        cameras: the rig, one camera per view, in the world frame of the result.
        max_frames: at most this many frames are matched, spread evenly over the sequence (the bundle
            adjustment uses a few hundred groups; matching every frame of a long capture would cost time for
            nothing).

    Returns:
        :class:`Regrouping` (empty when the association matched nobody in two views).

    Raises:
        ValueError: ``max_frames`` below 1, or inputs the association refuses (see
            :func:`~humancal.association.associate`).
    """
    if max_frames < 1:
        raise ValueError(f"max_frames must be at least 1, got {max_frames}")
    frames = np.unique(detections.frame)
    if len(frames) > max_frames:
        frames = frames[np.linspace(0, len(frames) - 1, max_frames).round().astype(int)]
    rows = np.flatnonzero(np.isin(detections.frame, frames))
    subset = DenseDetections(detections.frame[rows], detections.view[rows], detections.det_id[rows],
                             detections.keypoints_px[rows], detections.scores[rows])
    # clusters only: no temporal re-matching, no smoothing, no track rejected or merged
    config = TrackingConfig(temporal=False, smoothing=SmoothingConfig(enabled=False), min_track_s=0.0,
                            stitch_window_s=0.0)
    result = associate(subset, lifted.subset(rows), CameraRig.of(cameras), config)
    skeleton = {(int(f), int(p)): i for i, (f, p) in enumerate(zip(result.skeleton_frame, result.skeleton_person))}
    kept = np.flatnonzero(result.person_id >= 0)
    if len(kept) == 0:
        return Regrouping([], np.zeros((0, NUM_JOINTS, 3)), len(frames))
    kept = kept[np.lexsort((result.view[kept], result.person_id[kept], result.frame[kept]))]
    keys = np.c_[result.frame[kept], result.person_id[kept]]
    cuts = np.flatnonzero((np.diff(keys, axis=0) != 0).any(1)) + 1
    lifted_ok = lifted.valid[rows]
    groups, points = [], []
    for members in np.split(kept, cuts):
        index = skeleton.get((int(result.frame[members[0]]), int(result.person_id[members[0]])))
        members = members[lifted_ok[members]]  # the bundle adjustment compares each detection with its lifted pose
        if len(members) < 2 or index is None or not np.isfinite(result.joints_world_m[index]).any():
            continue
        groups.append(rows[members])
        points.append(result.joints_world_m[index])
    points_world_m = np.stack(points) if points else np.zeros((0, NUM_JOINTS, 3))
    return Regrouping(groups, points_world_m, len(frames))
