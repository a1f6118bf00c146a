"""Tracking over time: who is who across views and frames, and the people's 3D skeletons (the paper's
section III-C, ``docs/association.md``).

:func:`associate` runs the whole association of a sequence:

1. **Affinity** of every cross-view pair of every frame (:func:`~humancal.association.affinity.pair_affinities`).
2. **Matching**, all frames in one batch (or in chunks of frames: :data:`MAX_CHUNK_PAIRS`), without the temporal term
   (:func:`~humancal.association.cycle_matching.match_frames`): per frame, clusters of detections (one person,
   at most one detection per view) and unmatched detections.
3. **Triangulation** of every cluster, all at once: the confidence-weighted DLT and per-joint outlier-view
   rejection of :func:`humancal.geometry.triangulation.triangulate_dlt` (left-right flips), solved in closed form.
   Then the clusters are repaired: two clusters of a frame from different views that are one person split in
   two (their skeletons together, the larger one reprojecting onto the smaller one's detections) are merged
   (``merge_distance_m``), and a detection no cluster took joins the one cluster it fits
   (``complete_clusters``); what changed is triangulated again
   (:func:`~humancal.association.matched_clusters.triangulate_matchings`).
4. **Tracking**, frame by frame (:mod:`humancal.association.tracks`): clusters are assigned to tracks by the
   Hungarian method (``scipy.optimize.linear_sum_assignment``) on the median 3D joint distance to each track's
   predicted skeleton, gated by ``assign_distance_m``. A track that is not seen waits ``reid_window_s`` seconds; a
   cluster assigned to it after a gap (re-identification after an occlusion or after the person left the views) must
   also lie within the distance the person may have walked meanwhile and have the track's bone lengths. A cluster
   that matches no track starts one when it is seen by ``min_views`` views or more; a track observed for less than
   ``min_track_s`` seconds is rejected (its detections become ``-1``).
5. **Temporal term**: the affinities are scored again with each frame's detections against the tracks of the
   previous frame (:meth:`~humancal.association.affinity.PairAffinities.matrix` with
   :func:`~humancal.association.affinity.detection_track_affinity`); only the frames where this moves a pair
   across the match threshold are matched again (one batch), triangulated again, and tracking runs again.
6. **Number of people**: the tracks that survive, unless ``num_people`` is given; then at most that many ids
   are kept: the shortest surplus track is merged into a longer one it never overlaps in time and whose bone
   lengths it shares (the nearest at the junction), and dropped (its detections ``-1``) when no such track exists.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa

from humancal.association.affinity import detection_track_affinity, pair_affinities
from humancal.association.cluster_triangulation import cluster_observations
from humancal.association.cycle_matching import WarmStart, match_frames
from humancal.association.matched_clusters import MatchedClusters, TriangulationInputs, triangulate_matchings
from humancal.association.track_smoothing import smooth_tracks
from humancal.association.tracking_config import TrackingConfig
from humancal.association.tracks import build_tracks, keep_tracks
from humancal.camera import CameraRig
from humancal.keypoints import CANONICAL_JOINTS, NUM_JOINTS
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections
from humancal.tables.schemas import SCHEMAS, validate_table

__all__ = [
    "SKELETONS3D_SCHEMA",
    "AssociationResult",
    "TrackingConfig",
    "associate",
    "to_associations_table",
    "to_skeletons_table",
]

logger = logging.getLogger(__name__)


SKELETONS3D_SCHEMA = SCHEMAS["skeletons3d"]
"""The ``skeletons3d`` table (registered in :mod:`humancal.tables.schemas`): the triangulated 3D joints of every person
and frame, world metres, one row per (frame, person_id, joint); ``num_views`` views triangulated the joint in that
frame (0 with ``valid`` True: filled from the track's neighbouring frames by the smoothing; 0 and NaN coordinates:
missing, ``valid`` False)."""


@dataclass(frozen=True)
class AssociationResult:
    """Who is who in a sequence, and the 3D skeletons.

    Attributes:
        frame, view, det_id: (D,) int64 keys of the detections, in the input's row order.
        person_id: (D,) int64 person of every detection, 0..num_people-1 numbered by first appearance; -1:
            rejected (a false positive, or a detection no cluster took).
        skeleton_frame: (S,) int64 frame of every skeleton (sorted by frame, then person).
        skeleton_person: (S,) int64 person of every skeleton.
        joints_world_m: (S, 23, 3) triangulated canonical joints (refined over time by the smoothing when it is
            enabled), world frame, metres (NaN where missing).
        joint_views: (S, 23) int64 views each joint was triangulated from in its frame (0 where not: missing, or
            filled from the neighbouring frames where ``joints_world_m`` is finite).
        num_views: (S,) int64 detections (views) in the person's cluster of that frame.
        num_people: the number of people (estimated, or the one given where that many were found).
        stage_seconds: seconds per stage (``affinity``, ``matching``, ``triangulation``, ``tracking``,
            ``temporal``, ``smoothing``, ``total``).
        warnings: what went wrong without stopping the association (e.g. a view without detections).
    """

    frame: np.ndarray
    view: np.ndarray
    det_id: np.ndarray
    person_id: np.ndarray
    skeleton_frame: np.ndarray
    skeleton_person: np.ndarray
    joints_world_m: np.ndarray
    joint_views: np.ndarray
    num_views: np.ndarray
    num_people: int
    stage_seconds: dict[str, float]
    warnings: tuple[str, ...] = ()


# --------------------------------------------------------------------------------------------------------- input


def _check_inputs(detections: DenseDetections, lifted: LiftedPoses | None, rig: CameraRig) -> list[str]:
    """Raise on input nothing sensible can come from; return warnings for input that is odd but usable."""
    if len(rig) < 2:
        raise ValueError(f"associate needs at least 2 cameras to tell people apart across views, the rig has "
                         f"{len(rig)}")
    D = len(detections)
    if D == 0:
        raise ValueError("associate: there are no detections")
    view = np.asarray(detections.view)
    if view.min() < 0 or view.max() >= len(rig):
        raise ValueError(f"associate: detections use views {int(view.min())}..{int(view.max())} but the rig has "
                         f"{len(rig)} cameras (views 0..{len(rig) - 1})")
    if lifted is not None and len(lifted) != D:
        raise ValueError(f"associate: lifted poses must be row-aligned with the detections, {len(lifted)} vs {D}")
    seen = np.unique(view)
    if len(seen) < 2:
        raise ValueError(f"associate: every detection comes from view {int(seen[0])}; cross-view association "
                         "needs detections in at least 2 views")
    missing = sorted(set(range(len(rig))) - set(seen.tolist()))
    return [f"view {v} has no detections" for v in missing]


# --------------------------------------------------------------------------------------------------------- entry


def associate(detections: DenseDetections, lifted: LiftedPoses | None, rig: CameraRig,
              config: TrackingConfig = TrackingConfig()) -> AssociationResult:
    """Person ids of every detection across views and frames, and the people's triangulated 3D skeletons.

    See the module docstring for the stages.

    Args:
        detections: D detections of one sequence (any row order; ``det_id`` numbers the detections of a
            (frame, view)).
        lifted: their lifted 3D poses (row-aligned; crop or camera frames), or None for the geometric affinity
            alone.
        rig: the cameras (view index = row of the rig).
        config: the settings.

    Returns:
        The :class:`AssociationResult` (detections in the input's row order).

    Raises:
        ValueError: fewer than 2 cameras, no detections, detections of a single view, views the rig lacks,
            lifted poses not row-aligned.
    """
    start = time.perf_counter()
    warnings = _check_inputs(detections, lifted, rig)
    seconds: dict[str, float] = {}
    order, dense, lifted_sorted = _sorted_by_frame(detections, lifted)
    frames, first_rows = np.unique(dense.frame, return_index=True)
    frame_start = np.append(first_rows, len(dense.frame)).astype(np.int64)
    chunks = _FrameChunks(dense, lifted_sorted, rig, config, frame_start)
    matchings = []
    for chunk in range(len(chunks)):
        with _timed(seconds, "affinity"):
            _, matrices, views = chunks.affinities(chunk)
        with _timed(seconds, "matching"):
            matchings += match_frames(views, matrices, config.matching_config)
    with _timed(seconds, "triangulation"):
        inputs = TriangulationInputs.of(dense, rig)
        clusters = triangulate_matchings(matchings, frame_start, frames, inputs, config)
    with _timed(seconds, "tracking"):
        person = _track(clusters, config, warnings)
    seconds["temporal"] = 0.0
    if config.temporal and config.affinity.uses_pose and lifted is not None:
        changed = 0
        with _timed(seconds, "temporal"):
            for chunk in reversed(range(len(chunks))):  # the last chunk's affinities are kept, the others again
                pairs, matrices, views = chunks.affinities(chunk)
                lo, hi = chunks.bounds[chunk]
                part = matchings[lo:hi]
                changed += _rematch_with_tracks(pairs, matrices, views, part, clusters.frame, person,
                                                clusters.joints_world_m, config)
                matchings[lo:hi] = part
        if changed:
            with _timed(seconds, "triangulation"):
                clusters = triangulate_matchings(matchings, frame_start, frames, inputs, config)
            with _timed(seconds, "tracking"):
                person = _track(clusters, config, warnings)
    seconds["smoothing"] = 0.0
    joints = clusters.joints_world_m
    if config.smoothing.enabled and (person >= 0).any():
        with _timed(seconds, "smoothing"):
            joints = _smooth(clusters, person, inputs, config)
    person_id, num_people, rows = _people(clusters, person, order, config, warnings)
    seconds["total"] = time.perf_counter() - start
    return AssociationResult(
        frame=np.asarray(detections.frame, dtype=np.int64).copy(), view=np.asarray(detections.view, np.int64).copy(),
        det_id=np.asarray(detections.det_id, np.int64).copy(), person_id=person_id,
        skeleton_frame=clusters.frame[rows], skeleton_person=person[rows], joints_world_m=joints[rows],
        joint_views=clusters.joint_views[rows], num_views=clusters.num_views[rows], num_people=num_people,
        stage_seconds=seconds, warnings=tuple(warnings))


MAX_CHUNK_PAIRS = 1 << 20
"""Detection pairs (the squared detection counts of the frames) whose affinities and matching matrices are held at
once. The frames are scored and matched in chunks of consecutive frames of at most this many pairs (a frame with
more is a chunk of its own), so the association's memory does not grow with the number of frames (the matching
holds about 150 bytes per pair: a chunk of 1 M pairs about 150 MB). Every frame is matched on its own, so the
chunks give the same association as one batch."""


class _FrameChunks:
    """The frame-sorted detections cut into chunks of consecutive frames (:data:`MAX_CHUNK_PAIRS`), and each
    chunk's affinities (:func:`~humancal.association.affinity.pair_affinities`), computed when asked; the last
    chunk's are kept, so a sequence of one chunk is scored once."""

    def __init__(self, dense: DenseDetections, lifted: LiftedPoses | None, rig: CameraRig, config: TrackingConfig,
                 frame_start: np.ndarray) -> None:
        self.dense, self.lifted, self.rig, self.config, self.frame_start = dense, lifted, rig, config, frame_start
        self.bounds = _chunk_bounds(np.diff(frame_start) ** 2, MAX_CHUNK_PAIRS)
        self._kept: tuple[int, tuple] | None = None

    def __len__(self) -> int:
        return len(self.bounds)

    def affinities(self, chunk: int) -> tuple:
        """``(pairs, matrices, views)`` of the chunk's frames: the :class:`PairAffinities`, one matrix per frame
        (no temporal term) and each frame's views."""
        if self._kept is not None and self._kept[0] == chunk:
            return self._kept[1]
        lo, hi = self.bounds[chunk]
        rows = np.arange(self.frame_start[lo], self.frame_start[hi])
        d = self.dense
        part = DenseDetections(d.frame[rows], d.view[rows], d.det_id[rows], d.keypoints_px[rows], d.scores[rows])
        pairs = pair_affinities(part, None if self.lifted is None else self.lifted.subset(rows), self.rig,
                                self.config.affinity)
        views = [part.view[pairs.frame_start[i]:pairs.frame_start[i + 1]] for i in range(len(pairs.frames))]
        self._kept = (chunk, (pairs, pairs.matrices(), views))
        return self._kept[1]


def _chunk_bounds(costs: np.ndarray, budget: int) -> list[tuple[int, int]]:
    """``(first, end)`` index ranges of consecutive items whose ``costs`` add up to at most ``budget`` (an item
    above it alone); every item in exactly one range."""
    bounds, first, total = [], 0, 0
    for i, cost in enumerate(costs.tolist()):
        if i > first and total + cost > budget:
            bounds.append((first, i))
            first, total = i, 0
        total += cost
    if len(costs):
        bounds.append((first, len(costs)))
    return bounds


@contextmanager
def _timed(seconds: dict[str, float], stage: str) -> Iterator[None]:
    """Add the seconds the block takes to ``seconds[stage]``."""
    t0 = time.perf_counter()
    yield
    seconds[stage] = seconds.get(stage, 0.0) + time.perf_counter() - t0


def _sorted_by_frame(detections: DenseDetections, lifted: LiftedPoses | None
                     ) -> tuple[np.ndarray, DenseDetections, LiftedPoses | None]:
    """The (D,) stable order of the detections by frame, and the detections and lifted poses in that order."""
    frame = np.asarray(detections.frame, dtype=np.int64)
    order = np.argsort(frame, kind="stable")
    dense = DenseDetections(frame[order], np.asarray(detections.view, np.int64)[order],
                            np.asarray(detections.det_id, np.int64)[order],
                            np.asarray(detections.keypoints_px, np.float64)[order],
                            np.asarray(detections.scores, np.float64)[order])
    return order, dense, None if lifted is None else lifted.subset(order)


def _track(clusters: MatchedClusters, config: TrackingConfig, warnings: list[str]) -> np.ndarray:
    """(C,) person of every cluster (0..P-1 by first appearance; -1: rejected); ``warnings`` extended."""
    track_of = build_tracks(clusters.frame, clusters.joints_world_m, clusters.num_views, config)
    return keep_tracks(track_of, clusters.frame, clusters.joints_world_m, config, warnings)


def _smooth(clusters: MatchedClusters, person: np.ndarray, inputs: TriangulationInputs,
            config: TrackingConfig) -> np.ndarray:
    """(C, 23, 3) the clusters' joints refined over each person's track (world metres)."""
    points, weights = cluster_observations(clusters.cluster, len(clusters.frame), inputs.view, inputs.keypoints_px,
                                           inputs.scores, len(inputs.cameras))
    joints, _ = smooth_tracks(clusters.frame, person, clusters.joints_world_m, points, weights, inputs.cameras,
                              config.fps, config.smoothing)
    return joints


def _people(clusters: MatchedClusters, person: np.ndarray, order: np.ndarray, config: TrackingConfig,
            warnings: list[str]) -> tuple[np.ndarray, int, np.ndarray]:
    """(D,) person of every detection in the input's row order, the number of people, and the rows of the kept
    skeletons sorted by frame, then person; the warnings about the people found are added, and all are logged."""
    cluster = clusters.cluster
    keep = person >= 0
    det_person = np.empty(len(cluster), np.int64)
    det_person[order] = np.where(cluster >= 0, person[np.maximum(cluster, 0)] if len(person) else -1, -1)
    num_people = int(person.max()) + 1 if keep.any() else 0
    if num_people == 0:
        warnings.append("no person found: every detection is rejected (false positives, or no person seen by "
                        f"{config.min_views} views for {config.min_track_s} s)")
    if config.num_people is not None and num_people < config.num_people:
        warnings.append(f"num_people={config.num_people} was given but only {num_people} people were found")
    for w in warnings:
        logger.warning("associate: %s", w)
    rows = np.flatnonzero(keep)
    return det_person, num_people, rows[np.lexsort((person[rows], clusters.frame[rows]))]


def _rematch_with_tracks(pairs, matrices, views, matchings, sk_frame, person, joints, config) -> int:
    """Score every frame again with the temporal term against the previous frame's people and match again (one
    batch) the frames where it moves a pair across the threshold against the frame's clusters (a pair of one
    cluster falls below it, or a pair of two rises above it); ``matchings`` is updated in place.

    Returns:
        The number of frames matched again.
    """
    threshold = config.match_threshold
    tracked = person >= 0
    frames_with = sk_frame[tracked]
    joints_with = joints[tracked]
    lo = np.searchsorted(frames_with, pairs.frames - 1, side="left")
    hi = np.searchsorted(frames_with, pairs.frames - 1, side="right")
    redo, redo_matrices = [], []
    for i, f in enumerate(pairs.frames.tolist()):
        if hi[i] == lo[i] or len(views[i]) < 2:
            continue
        rows = np.arange(pairs.frame_start[i], pairs.frame_start[i + 1])
        T = detection_track_affinity(pairs.geometry, rows, joints_with[lo[i]:hi[i]], config.affinity)
        A = pairs.matrix(f, T)
        c = matchings[i].cluster
        together = (c[:, None] == c[None, :]) & (c[:, None] >= 0)
        above = A > threshold
        if ((above != (matrices[i] > threshold)) & (above != together)).any():
            redo.append(i)
            redo_matrices.append(A)
    if redo:
        # each frame starts from its own first solution (the same detections; the temporal term moves few pairs)
        starts = [WarmStart(matchings[i].relaxed, matchings[i].dual) for i in redo]
        again = match_frames([views[i] for i in redo], redo_matrices, config.matching_config, starts)
        for i, m in zip(redo, again):
            matchings[i] = m
    logger.debug("associate: the temporal term changed %d of %d frames", len(redo), len(pairs.frames))
    return len(redo)


# -------------------------------------------------------------------------------------------------------- tables


def to_associations_table(result: AssociationResult, sequence: str) -> pd.DataFrame:
    """The canonical ``associations`` table (sequence, frame, view, det_id, person_id) of a result."""
    table = pd.DataFrame({"sequence": sequence, "frame": result.frame, "view": result.view,
                          "det_id": result.det_id, "person_id": result.person_id})
    table = table.sort_values(["frame", "view", "det_id"], kind="stable").reset_index(drop=True)
    return validate_table(table, "associations")


def to_skeletons_table(result: AssociationResult, sequence: str) -> pd.DataFrame:
    """The tidy 3D skeletons of a result, columns of :data:`SKELETONS3D_SCHEMA` (one row per frame, person and
    joint, all 23 joints of every skeleton)."""
    S = len(result.skeleton_frame)
    xyz = result.joints_world_m.reshape(-1, 3)
    table = pd.DataFrame({
        "sequence": sequence,
        "frame": np.repeat(result.skeleton_frame, NUM_JOINTS).astype(np.int32),
        "person_id": np.repeat(result.skeleton_person, NUM_JOINTS).astype(np.int32),
        "joint": np.tile(np.asarray(CANONICAL_JOINTS, dtype=object), S),
        "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2],
        "num_views": result.joint_views.reshape(-1).astype(np.int32),
        "valid": np.isfinite(xyz).all(-1),
    })
    return pa.Table.from_pandas(table, schema=SKELETONS3D_SCHEMA, preserve_index=False).to_pandas()
