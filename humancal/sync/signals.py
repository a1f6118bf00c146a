"""Per-view motion signals: each tracked person's pose over time, in quantities that do not depend on the camera,
so that two views of the same person give the same curves shifted in time.

A person is a track of :func:`humancal.sync.tracks.link_view_tracks` (no identity across views is known). Per
detection, the signal holds (``kind``):

- ``"lifted"``: from the lifter's root-relative 3D pose, the angles at the elbows, shoulders, hips and knees
  (radians) and the distances between wrists, ankles, knees and hips (metres). Angles and
  distances between joints do not depend on the frame the pose is expressed in, so apart from the lifter's errors
  they are the same numbers in every view;
- ``"2d"``: the same angles and distances measured in the image (distances in units of the person's size). No
  lifter is needed, but a limb seen end-on looks bent, so the curves differ between views;
- ``"both"``: the channels of the two side by side.

Speeds (differences between frames) were tried first and measured worse: the detector's jitter dominates a
frame-to-frame difference, while the values themselves (a bent knee, a raised arm) stand well above it
(``docs/capture.md``, "Unsynchronised videos"). The values are smoothed along each track (a Gaussian of
``smooth_frames``), frames where the person is not detected get weight 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from humancal.geometry.rotations import angle_between_deg
from humancal.keypoints import JOINT_INDEX
from humancal.sync.tracks import link_view_tracks, person_size_px
from humancal.tables.detections import DenseDetections

__all__ = ["SIGNAL_KINDS", "TrackSignals", "joint_distances", "pose_features", "track_signals"]

SIGNAL_KINDS: tuple[str, ...] = ("lifted", "2d", "both")
"""The signals :func:`track_signals` builds (module docstring)."""

_J = JOINT_INDEX
# (joint at the vertex, the two joints at the ends of its bones)
_ANGLES = (("left_elbow", "left_shoulder", "left_wrist"), ("right_elbow", "right_shoulder", "right_wrist"),
           ("left_shoulder", "left_hip", "left_elbow"), ("right_shoulder", "right_hip", "right_elbow"),
           ("left_knee", "left_hip", "left_ankle"), ("right_knee", "right_hip", "right_ankle"),
           ("left_hip", "left_shoulder", "left_knee"), ("right_hip", "right_shoulder", "right_knee"))
_DISTANCES = (("left_ankle", "right_ankle"), ("left_wrist", "right_wrist"), ("left_wrist", "left_hip"),
              ("right_wrist", "right_hip"), ("left_ankle", "left_hip"), ("right_ankle", "right_hip"),
              ("left_knee", "right_knee"))
_CHANNELS = tuple(f"angle_{v}" for v, _, _ in _ANGLES) + tuple(f"distance_{a}_{b}" for a, b in _DISTANCES)


@dataclass(frozen=True)
class TrackSignals:
    """One view's tracked people and their pose signals on the view's own frames.

    Attributes:
        first_frame: the view's frame number of column 0.
        values: (T, F, C) per track, frame and channel (0 where the person is not detected).
        weight: (T, F, C) 1 where the track has a detection with that channel known, else 0.
        channels: (C,) channel names (radians for angles, person heights or sizes for distances).
        pose_m: (T, F, P) the distance between every two of the 23 joints (P = 253) of the lifter's pose, metres,
            unsmoothed (NaN where the track has no lifted detection); None without lifted poses. Used to pick the
            integer lag of a pair of views (:func:`humancal.sync.correlation.pose_distance`).
    """

    first_frame: int
    values: np.ndarray
    weight: np.ndarray
    channels: tuple[str, ...]
    pose_m: np.ndarray | None = None


def pose_features(joints: np.ndarray, size: np.ndarray) -> np.ndarray:
    """(D, C) joint angles (radians) and distances between joints (in units of ``size``) of each pose.

    Args:
        joints: (D, 23, 2) or (D, 23, 3) keypoints in any frame and unit (NaN where missing).
        size: (D,) the person's size in the unit of ``joints``.

    Returns:
        (D, 15) features, NaN where a joint they need is missing.
    """
    out = np.empty((len(joints), len(_ANGLES) + len(_DISTANCES)))
    if joints.shape[-1] == 2:  # image keypoints: the angle between 2D directions is the one in their plane z = 0
        joints = np.concatenate([joints, np.zeros(joints.shape[:-1] + (1,))], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        for a, (vertex, p, q) in enumerate(_ANGLES):
            u = joints[:, _J[p]] - joints[:, _J[vertex]]
            w = joints[:, _J[q]] - joints[:, _J[vertex]]
            out[:, a] = np.deg2rad(angle_between_deg(u, w))
        for k, (p, q) in enumerate(_DISTANCES):
            out[:, len(_ANGLES) + k] = np.linalg.norm(joints[:, _J[p]] - joints[:, _J[q]], axis=-1) / size
    return out


_PAIRS = np.triu_indices(len(_J), 1)
"""The joint pairs of :func:`joint_distances` for the 23 canonical joints."""


def joint_distances(joints: np.ndarray) -> np.ndarray:
    """(D, P) the distance between every two joints of each pose (P = J (J - 1) / 2, pairs in ``np.triu_indices``
    order), in the unit of ``joints``: a description of the pose that does not depend on the frame it is expressed
    in.

    Args:
        joints: (D, J, 3) poses (NaN where missing).
    """
    i, k = np.triu_indices(joints.shape[1], 1)
    return np.linalg.norm(joints[:, i] - joints[:, k], axis=-1)


def _features(dense: DenseDetections, rows: np.ndarray, kind: str, joints_m: np.ndarray | None
              ) -> tuple[np.ndarray, tuple[str, ...]]:
    parts, names = [], []
    if kind in ("lifted", "both"):
        # metres: the lifter gives every pose its person's metric size (rows it did not lift are NaN, so are
        # their features)
        parts.append(pose_features(joints_m[rows], np.ones(len(rows))))
        names += [f"lifted_{c}" for c in _CHANNELS]
    if kind in ("2d", "both"):
        valid = dense.valid[rows]
        kp = np.where(valid[..., None], dense.keypoints_px[rows], np.nan)
        parts.append(pose_features(kp, person_size_px(dense.keypoints_px[rows], valid)))
        names += [f"image_{c}" for c in _CHANNELS]
    return np.concatenate(parts, axis=1), tuple(names)


def track_signals(dense: DenseDetections, view: int, kind: str = "lifted", *, joints_m: np.ndarray | None = None,
                  smooth_frames: float = 1.5, min_track_frames: int = 15, max_step: float = 0.25) -> TrackSignals:
    """The pose signals of one view's tracked people.

    Args:
        dense: the capture's detections.
        view: the view.
        kind: one of :data:`SIGNAL_KINDS`.
        joints_m: (D, 23, 3) the lifter's root-relative poses row-aligned with ``dense`` (NaN rows where not
            lifted), metres, in any per-detection frame; needed for ``"lifted"`` and ``"both"``.
        smooth_frames: std of the Gaussian that smooths each track's values over time, frames (0: none); gaps are
            not filled (the smoothing is normalised by the smoothed weight).
        min_track_frames: shorter tracks are left out (too short to correlate).
        max_step: the tracker's gate (:func:`humancal.sync.tracks.link_view_tracks`), person sizes per frame.

    Returns:
        The :class:`TrackSignals` over the view's frames from its first to its last detection (no track: T = 0).

    Raises:
        ValueError: an unknown ``kind``, lifted poses missing or of the wrong shape, or a view without detections.
    """
    if kind not in SIGNAL_KINDS:
        raise ValueError(f"kind: expected one of {list(SIGNAL_KINDS)}, got {kind!r}")
    if kind != "2d" and (joints_m is None or np.shape(joints_m) != (len(dense), dense.keypoints_px.shape[1], 3)):
        raise ValueError(f"kind {kind!r} needs joints_m of shape ({len(dense)}, 23, 3), got "
                         f"{None if joints_m is None else np.shape(joints_m)}")
    rows = np.flatnonzero(dense.view == view)
    if not len(rows):
        raise ValueError(f"view {view} has no detections")
    first, last = int(dense.frame[rows].min()), int(dense.frame[rows].max())
    track = link_view_tracks(dense, view, max_step=max_step)
    rows = rows[track[rows] >= 0]
    ids, counts = np.unique(track[rows], return_counts=True)
    ids = ids[counts >= min_track_frames]
    rows = rows[np.isin(track[rows], ids)]
    features, names = _features(dense, rows, kind, joints_m)
    T, F, C = len(ids), last - first + 1, features.shape[1]
    values = np.zeros((T, F, C))
    weight = np.zeros((T, F, C))
    t = np.searchsorted(ids, track[rows])
    f = dense.frame[rows] - first
    known = np.isfinite(features)
    values[t, f] = np.where(known, features, 0.0)
    weight[t, f] = known
    if smooth_frames > 0 and T:
        smoothed_w = gaussian_filter1d(weight, smooth_frames, axis=1, mode="constant")
        with np.errstate(invalid="ignore", divide="ignore"):
            values = np.where(weight > 0, gaussian_filter1d(values * weight, smooth_frames, axis=1, mode="constant")
                              / smoothed_w, 0.0)
    present = np.zeros((T, F))
    present[t, f] = 1.0
    pose = None
    if joints_m is not None:
        pose = np.full((T, F, len(_PAIRS[0])), np.nan)
        pose[t, f] = joint_distances(joints_m[rows])
    return TrackSignals(first, values, weight * present[..., None], names, pose)
