"""Affinity between the detections of one frame: how likely two detections (or a detection and a track) are
one person (the paper's section III-C, ``docs/association.md``).

Three similarities, each in [0, 1]:

* **geometric** (:func:`pair_affinities`): the back-projected rays of corresponding joints of two detections in
  different views meet when both see the same person. In Plücker coordinates (unit direction ``d``, moment
  ``m = c x d`` for a ray from the camera centre ``c``) two lines meet iff their reciprocal product
  ``d_a . m_b + d_b . m_a`` is 0; divided by ``|d_a x d_b|`` it is the distance between the lines in metres.
  Each joint seen by both scores ``max(0, 1 - distance / ray_distance_scale_m)``; the joints are averaged with
  the weights ``sqrt(score_a * score_b)``. This alone is the baseline ``epipolar_only``.
* **spatial pose** (:func:`pair_affinities`): the lifted 3D poses turned into the world by the cameras'
  rotations and placed by a translation that fits them to their 2D keypoints. Three distances, each through
  ``exp(-(distance / scale)^2 / 2)`` and multiplied: the root-relative poses joint by joint (the paper's
  ``||X_i - X_j||``), the same after the best rigid alignment (Procrustes: the body poses alike, whatever the
  cameras' rotation errors), and the placed hip midpoints (the positions consistent), after sliding both along
  their rays by one common factor in ``depth_scale_range`` (the lifter's size error is shared by the views).
* **temporal** (:func:`detection_track_affinity`): a detection against each track's previous world joints: the
  distances of those joints to the detection's joint rays, scored like the geometric term with
  ``temporal_scale_m``.

They combine as the paper's equation: ``geometric_weight * G + pose_weight * P`` (0.7 and 0.3, normalised by
their sum), where ``P`` is the spatial pose similarity, averaged with the pair's temporal similarity when tracks
are given (:meth:`PairAffinities.matrix`). Everything is vectorised over all cross-view pairs of all frames.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from humancal.association.detection_geometry import DetectionGeometry, detection_geometry, ray_distances_m
from humancal.camera import CameraRig
from humancal.config import Config, at_least, in_range, positive
from humancal.geometry.alignment import best_rotation_trace
from humancal.keypoints import NUM_JOINTS
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = [
    "AffinityConfig",
    "PairAffinities",
    "combine_affinity",
    "cross_view_pairs",
    "pair_affinities",
    "detection_track_affinity",
]

logger = logging.getLogger(__name__)

_CHUNK_PAIRS = 16384
"""Pairs per vectorised block (bounds the memory of the (pairs, 23, 3) stacks; results do not depend on it)."""


@dataclass(frozen=True)
class AffinityConfig(Config):
    """Weights and scales of the affinity (defaults: the paper's weights; scales set on synthetic scenes,
    ``docs/association.md``).

    Attributes:
        geometric_weight: weight ``c_g`` of the geometric (ray coplanarity) term, >= 0.
        pose_weight: weight ``c_p`` of the pose term (spatial and temporal), >= 0; 0 gives ``epipolar_only``.
        ray_distance_scale_m: a joint's ray-to-ray (or point-to-ray) distance at which its similarity reaches 0,
            metres.
        pose_scale_m: RMS joint distance of the root-relative world poses where the pose factor is
            ``exp(-1/2)``, metres.
        shape_scale_m: the same for the RMS distance after rigid alignment, metres.
        position_scale_m: the same for the distance of the placed hip midpoints, metres.
        depth_scale_range: (low, high) common factor by which the two placed hip midpoints may slide along
            their rays before their distance is taken (the lifter cannot see a person's absolute size, so its
            depths share one error per person).
        temporal_scale_m: like ``ray_distance_scale_m`` for a track's previous joints to a detection's rays
            (larger: people move between frames), metres.
        min_common_joints: a pair (or a detection and a track) sharing fewer joints has affinity 0.
    """

    geometric_weight: float = field(default=0.7, metadata=at_least(0))
    pose_weight: float = field(default=0.3, metadata=at_least(0))
    ray_distance_scale_m: float = field(default=0.3, metadata=positive())
    pose_scale_m: float = field(default=0.25, metadata=positive())
    shape_scale_m: float = field(default=0.15, metadata=positive())
    position_scale_m: float = field(default=0.5, metadata=positive())
    depth_scale_range: tuple[float, float] = (0.8, 1.25)
    temporal_scale_m: float = field(default=0.3, metadata=positive())
    min_common_joints: int = field(default=3, metadata=in_range(1, NUM_JOINTS, integer=True))

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.geometric_weight + self.pose_weight <= 0.0:
            raise ValueError("AffinityConfig: geometric_weight + pose_weight must be > 0, got 0")
        low, high = self.depth_scale_range
        if not 0.0 < low <= 1.0 <= high < np.inf:
            raise ValueError(f"AffinityConfig.depth_scale_range must be (low, high) with 0 < low <= 1 <= high, "
                             f"got {self.depth_scale_range}")

    @classmethod
    def epipolar_only(cls, **overrides: object) -> AffinityConfig:
        """The baseline ``epipolar_only``: the geometric term alone (pose weight 0)."""
        return cls(**{"geometric_weight": 1.0, "pose_weight": 0.0, **overrides})

    @property
    def uses_pose(self) -> bool:
        """Whether the pose terms count (``pose_weight > 0``)."""
        return self.pose_weight > 0.0


def cross_view_pairs(frame: np.ndarray, view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of detections of one frame in different views.

    Args:
        frame, view: (D,) int, rows sorted by frame (any order within a frame).

    Returns:
        (rows_a, rows_b): (P,) detection rows with ``rows_a < rows_b``, ordered by frame then ``rows_a``.

    Raises:
        ValueError: rows not sorted by frame.
    """
    frame, view = np.asarray(frame, dtype=np.int64), np.asarray(view, dtype=np.int64)
    if len(frame) and (np.diff(frame) < 0).any():
        raise ValueError("cross_view_pairs: detections must be sorted by frame")
    D = len(frame)
    if D == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    _, start, count = np.unique(frame, return_index=True, return_counts=True)
    end = np.repeat(start + count, count)
    later = end - np.arange(D) - 1
    a = np.repeat(np.arange(D), later)
    offset = np.arange(len(a)) - np.repeat(np.cumsum(later) - later, later)
    b = a + 1 + offset
    keep = view[a] != view[b]
    return a[keep], b[keep]


def _ray_similarity(geo: DetectionGeometry, a: np.ndarray, b: np.ndarray, scale_m: float,
                    min_common: int) -> tuple[np.ndarray, np.ndarray]:
    """(P,) confidence-weighted joint similarity of the rays of pairs (a, b), and (P,) common joint counts."""
    joint_sim = np.maximum(0.0, 1.0 - ray_distances_m(geo, a, b) / scale_m)
    w = np.sqrt(geo.scores[a] * geo.scores[b])
    common = (w > 0).sum(1)
    joint_sim = np.where(w > 0, joint_sim, 0.0)
    total = w.sum(1)
    sim = np.where(common >= min_common, (w * joint_sim).sum(1) / np.where(total > 0, total, 1.0), 0.0)
    return sim, common


def _centred_poses(geo: DetectionGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per detection: (D, 23, 3) world pose minus its centroid, (D, 3) centroid, (D,) squared norm of the first."""
    mean = geo.pose_world_m.mean(1)
    centred = geo.pose_world_m - mean[:, None]
    return centred, mean, (centred * centred).sum((1, 2))


def _pose_similarity(geo: DetectionGeometry, centred: tuple[np.ndarray, np.ndarray, np.ndarray], a: np.ndarray,
                     b: np.ndarray, config: AffinityConfig) -> np.ndarray:
    """(P,) spatial pose similarity of pairs (a, b), both with a lifted pose and a placed root."""
    # one cross-covariance M = A^T B of the centred poses per pair gives both distances:
    # sum_j |pa_j - pb_j|^2 = |A|^2 + |B|^2 - 2 tr M + J |mu_a - mu_b|^2, and the rigid residual
    # |A|^2 + |B|^2 - 2 max_R tr(R^T M)
    poses, mean, norm2 = centred
    M = np.swapaxes(poses[a], 1, 2) @ poses[b]
    base = norm2[a] + norm2[b]
    mean_gap = ((mean[a] - mean[b]) ** 2).sum(-1)
    pose_rms = np.sqrt(np.maximum((base - 2.0 * np.trace(M, axis1=1, axis2=2)) / NUM_JOINTS + mean_gap, 0.0))
    shape_rms = np.sqrt(np.maximum(base - 2.0 * best_rotation_trace(M), 0.0) / NUM_JOINTS)
    # the hip midpoints slide along their rays by one common factor (the lifter's size error is the person's)
    centre_gap = geo.centres_world_m[a] - geo.centres_world_m[b]
    ray_gap = (geo.root_world_m[a] - geo.centres_world_m[a]) - (geo.root_world_m[b] - geo.centres_world_m[b])
    factor = -(centre_gap * ray_gap).sum(-1) / np.maximum((ray_gap * ray_gap).sum(-1), 1e-12)
    factor = np.clip(factor, *config.depth_scale_range)
    position = np.linalg.norm(centre_gap + factor[:, None] * ray_gap, axis=-1)
    return np.exp(-0.5 * ((pose_rms / config.pose_scale_m) ** 2 + (shape_rms / config.shape_scale_m) ** 2
                          + (position / config.position_scale_m) ** 2))


@dataclass(frozen=True)
class PairAffinities:
    """Affinities of all cross-view pairs of all frames, and the per-frame matrices the matching consumes.

    Attributes:
        frame: (D,) frame of each detection (rows sorted by frame).
        view: (D,) view of each detection.
        frames: (F,) the distinct frames, increasing.
        frame_start: (F + 1,) detection rows of ``frames[i]`` are ``frame_start[i]:frame_start[i + 1]``.
        rows_a, rows_b: (P,) the pairs (detection rows, ``rows_a < rows_b``, same frame, different views).
        geometric: (P,) geometric similarity in [0, 1].
        pose: (P,) spatial pose similarity in [0, 1] (NaN where a detection has no lifted pose, or the pose
            terms are off).
        common_joints: (P,) joints both detections see.
        combined: (P,) the combined affinity in [0, 1] without temporal term.
        config: the settings used.
        geometry: the detections' rays and world poses (for :func:`detection_track_affinity`; no poses when
            the pose terms are off).
    """

    frame: np.ndarray
    view: np.ndarray
    frames: np.ndarray
    frame_start: np.ndarray
    rows_a: np.ndarray
    rows_b: np.ndarray
    geometric: np.ndarray
    pose: np.ndarray
    common_joints: np.ndarray
    combined: np.ndarray
    config: AffinityConfig
    geometry: DetectionGeometry

    def frame_rows(self, frame: int) -> np.ndarray:
        """(n,) detection rows of one frame (empty for a frame without detections)."""
        i = np.searchsorted(self.frames, frame)
        if i == len(self.frames) or self.frames[i] != frame:
            return np.zeros(0, np.int64)
        return np.arange(self.frame_start[i], self.frame_start[i + 1])

    def matrix(self, frame: int, track_affinity: np.ndarray | None = None) -> np.ndarray:
        """The (n, n) symmetric affinity matrix over the detections of one frame (rows of :meth:`frame_rows`).

        1 on the diagonal, 0 between two detections of one view and where a pair shares fewer than
        ``min_common_joints`` joints.

        Args:
            frame: the frame.
            track_affinity: optional (n, T) :func:`detection_track_affinity` of the frame's detections against
                the T live tracks. Where given, the pose term of a pair becomes the mean of its spatial
                similarity and its temporal one, ``max_t min(track_affinity[i, t], track_affinity[j, t])``
                (both detections agree with one track); pairs of which neither detection is near any track
                (new people) keep the spatial term alone.

        Returns:
            (n, n) float64 in [0, 1].

        Raises:
            ValueError: track_affinity of the wrong shape.
        """
        rows = self.frame_rows(frame)
        n = len(rows)
        out = np.eye(n)
        if n == 0:
            return out
        lo, hi = np.searchsorted(self.rows_a, [rows[0], rows[-1] + 1])
        a, b = self.rows_a[lo:hi] - rows[0], self.rows_b[lo:hi] - rows[0]
        values = self.combined[lo:hi]
        if track_affinity is not None:
            T = np.asarray(track_affinity, dtype=np.float64)
            if T.ndim != 2 or T.shape[0] != n:
                raise ValueError(f"track_affinity must have shape ({n}, T) for frame {frame}, got {T.shape}")
            if T.shape[1] and self.config.uses_pose:
                values = self._with_temporal(lo, hi, a, b, T)
        out[a, b] = values
        out[b, a] = values
        return out

    def _with_temporal(self, lo: int, hi: int, a: np.ndarray, b: np.ndarray, T: np.ndarray) -> np.ndarray:
        temporal = np.minimum(T[a], T[b]).max(1)
        informative = (T[a].max(1) > 0) | (T[b].max(1) > 0)
        spatial = self.pose[lo:hi]
        pose = np.where(informative, 0.5 * (np.nan_to_num(spatial, nan=temporal) + temporal), spatial)
        return combine_affinity(self.geometric[lo:hi], pose, self.common_joints[lo:hi], self.config)

    def matrices(self) -> list[np.ndarray]:
        """One :meth:`matrix` per frame of ``frames`` (no temporal term)."""
        return [self.matrix(int(f)) for f in self.frames]


def combine_affinity(
    geometric: np.ndarray, pose: np.ndarray, common_joints: np.ndarray, config: AffinityConfig
) -> np.ndarray:
    """The paper's combination ``(c_g G + c_p P) / (c_g + c_p)`` per pair.

    Args:
        geometric, pose: (P,) similarities in [0, 1]; a NaN pose (no lifted pose) leaves the pose term out
            (the geometric term alone).
        common_joints: (P,) joints both detections see; fewer than ``config.min_common_joints`` gives 0.
        config: the weights.

    Returns:
        (P,) affinities in [0, 1], never NaN.
    """
    cg, cp = config.geometric_weight, config.pose_weight
    has_pose = np.isfinite(pose) & (cp > 0)
    value = np.where(has_pose, (cg * geometric + cp * np.nan_to_num(pose)) / (cg + cp), geometric)
    if cg == 0:
        value = np.where(has_pose, value, 0.0)
    return np.where(common_joints >= config.min_common_joints, np.clip(value, 0.0, 1.0), 0.0)


def pair_affinities(
    detections: DenseDetections,
    lifted: LiftedPoses | None,
    rig: CameraRig,
    config: AffinityConfig = AffinityConfig(),
) -> PairAffinities:
    """Geometric, spatial pose and combined affinities of every cross-view pair of every frame, vectorised.

    Args:
        detections: D detections, rows sorted by frame (``detections_to_dense`` sorts them so).
        lifted: their lifted poses (row-aligned; crop or camera frames), or None (only the geometric term: the
            combination is then ``epipolar_only`` whatever the weights).
        rig: the current cameras.
        config: weights and scales.

    Returns:
        The :class:`PairAffinities` (per-frame matrices with :meth:`PairAffinities.matrix`).

    Raises:
        ValueError: rows not sorted by frame, lifted poses not row-aligned, or views missing from the rig.
    """
    geo = detection_geometry(detections, lifted if config.uses_pose else None, rig)
    a, b = cross_view_pairs(geo.frame, geo.view)
    P = len(a)
    geometric, pose = np.zeros(P), np.full(P, np.nan)
    common = np.zeros(P, np.int64)
    use_pose = config.uses_pose and lifted is not None
    valid = geo.pose_valid
    centred = _centred_poses(geo) if use_pose else None
    for lo in range(0, P, _CHUNK_PAIRS):
        ca, cb = a[lo : lo + _CHUNK_PAIRS], b[lo : lo + _CHUNK_PAIRS]
        geometric[lo : lo + len(ca)], common[lo : lo + len(ca)] = _ray_similarity(
            geo, ca, cb, config.ray_distance_scale_m, config.min_common_joints)
        if use_pose:
            both = valid[ca] & valid[cb]
            block = np.full(len(ca), np.nan)
            if both.any():
                block[both] = _pose_similarity(geo, centred, ca[both], cb[both], config)
            pose[lo : lo + len(ca)] = block
    frames, start = np.unique(geo.frame, return_index=True)
    frame_start = np.append(start, len(geo)).astype(np.int64)
    logger.debug("affinity: %d detections, %d frames, %d cross-view pairs", len(geo), len(frames), P)
    return PairAffinities(geo.frame, geo.view, frames, frame_start, a, b, geometric, pose, common,
                          combine_affinity(geometric, pose, common, config), config, geo)


def detection_track_affinity(
    geometry: DetectionGeometry,
    rows: np.ndarray,
    track_joints_world_m: np.ndarray,
    config: AffinityConfig = AffinityConfig(),
) -> np.ndarray:
    """Temporal similarity of detections to tracks: the tracks' previous world joints against the detections'
    joint rays.

    Each joint both sides have scores ``max(0, 1 - distance / temporal_scale_m)`` with the distance of the
    track's joint to the detection's ray (metres: the reprojection error measured at the person's depth); the
    joints are averaged with the detection's confidences.

    Args:
        geometry: from :func:`detection_geometry`.
        rows: (n,) detection rows to score (e.g. :meth:`PairAffinities.frame_rows`).
        track_joints_world_m: (T, 23, 3) each track's last world joints, metres (NaN where unknown).
        config: ``temporal_scale_m`` and ``min_common_joints``.

    Returns:
        (n, T) similarities in [0, 1] (0 where fewer than ``min_common_joints`` joints are shared), never NaN.

    Raises:
        ValueError: track joints not (T, 23, 3).
    """
    X = np.asarray(track_joints_world_m, dtype=np.float64)
    if X.ndim != 3 or X.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f"track_joints_world_m must have shape (T, {NUM_JOINTS}, 3), got {X.shape}")
    rows = np.asarray(rows, dtype=np.int64)
    d = geometry.rays_world[rows].astype(np.float64)[:, None]  # (n, 1, J, 3)
    c = geometry.centres_world_m[rows][:, None, None, :]
    offset = X[None] - c  # (n, T, J, 3)
    along = (offset * d).sum(-1, keepdims=True)
    distance = np.linalg.norm(offset - along * d, axis=-1)
    w = np.where(np.isfinite(distance) & (along[..., 0] > 0), geometry.scores[rows][:, None, :], 0.0)
    joint_sim = np.where(w > 0, np.maximum(0.0, 1.0 - distance / config.temporal_scale_m), 0.0)
    total = w.sum(-1)
    sim = (w * joint_sim).sum(-1) / np.where(total > 0, total, 1.0)
    return np.where((w > 0).sum(-1) >= config.min_common_joints, sim, 0.0)
