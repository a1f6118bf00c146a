"""A view's detections at times between its frames: linear interpolation along the view's 2D tracks.

A view ``v`` filmed its frames at its own times; another clock asks for its people at time ``t``, which falls at the
view's (fractional) frame ``s = (t - offset_v) fps_v`` (``docs/conventions.md``, "Time"). Taking the frame nearest
to ``s`` leaves up to half a frame of the view's clock: 17 ms at 30 fps, 2.3 cm of a person walking at 1.4 m/s.
:func:`view_at_times` links the view's detections into tracks (:func:`humancal.sync.link_view_tracks`, no camera
needed) and, for each time asked for and each track, blends the two detections of the track around ``s``:

- joints detected in both: ``(1 - w) x_before + w x_after`` with ``w = s - floor(s)``, the scores blended alike;
- joints detected in only one of them: the nearer detection's joint as it is, or none when only the farther one
  has it;
- a partner detected left-right flipped (the tracker links such pairs) is flipped back first;
- ``s`` on a frame (within 1e-6 of one): that frame's detections as they are, tracked or not;
- no detection of the track on the other side (the first or last frame of a track, a frame missed by the detector,
  a detection too sparse to be tracked): the nearest frame's detection as it is, its remainder reported.

Joint positions are blended, not rotations: between two frames at 25-60 fps a joint moves a few pixels along an arc
whose chord is off it by far less than a detector's noise.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.formats.detections.table import sort_detections
from humancal.keypoints import FLIP_INDEX
from humancal.sync.tracks import link_view_tracks
from humancal.tables.detections import DenseDetections, dense_to_detections, detections_to_dense

__all__ = ["ViewAtTimes", "view_at_times", "views_at_times"]

_ON_FRAME = 1e-6
"""A time within this many of the view's frames from a frame is that frame."""


@dataclass(frozen=True)
class ViewAtTimes:
    """One view's detections at the times asked for.

    Attributes:
        detections: the detections, ``frame`` the index of the time asked for (``det_id`` that of the nearer
            detection it came from, unique per time).
        remainder_frames: (D,) ``s`` minus the frame each detection was taken from, in the view's frames: 0 where
            interpolated or on a frame, up to +-0.5 where the nearest frame was taken for want of a partner.
        interpolated: (D,) whether each detection is a blend of two frames.
        used_frames: the view's frames whose detections went into some output, sorted.
    """

    detections: DenseDetections
    remainder_frames: np.ndarray
    interpolated: np.ndarray
    used_frames: np.ndarray


def view_at_times(dense: DenseDetections, view: int, source_frames: np.ndarray) -> ViewAtTimes:
    """The people of view ``view`` at the fractional frames ``source_frames`` of its own clock.

    Args:
        dense: a capture's detections, each view's ``frame`` on its own clock (only ``view``'s rows are used).
        view: the view.
        source_frames: (M,) for each time asked for, the view's own frame at that time (NaN: none asked).

    Returns:
        The :class:`ViewAtTimes`: at most one detection per track and time, ``frame`` in ``0 .. M-1``.
    """
    source_frames = np.asarray(source_frames, dtype=np.float64).reshape(-1)
    rows = np.flatnonzero(dense.view == view)
    track = link_view_tracks(dense, view)[rows]
    lone = track < 0  # too few joints to be tracked: each its own track, so that it can only be taken as it is
    track[lone] = track.max(initial=-1) + 1 + np.arange(lone.sum())
    frames = dense.frame[rows].astype(np.int64)

    # pair every detection with the times whose nearest frame is its own
    asked = np.flatnonzero(np.isfinite(source_frames))
    s = source_frames[asked]
    nearest = np.floor(s + 0.5).astype(np.int64)
    order = np.argsort(nearest, kind="stable")
    asked, s, nearest = asked[order], s[order], nearest[order]
    lo = np.searchsorted(nearest, frames, side="left")
    count = np.searchsorted(nearest, frames, side="right") - lo
    pick = np.repeat(np.arange(len(rows)), count)
    position = np.repeat(lo - np.cumsum(count) + count, count) + np.arange(count.sum())
    target, fraction = asked[position], s[position] - frames[pick]

    # the same track's detection on the other side of the time
    side = np.where(np.abs(fraction) < _ON_FRAME, 0, np.sign(fraction)).astype(np.int64)
    partner = _lookup(track, frames, track[pick], frames[pick] + side)
    partner[side == 0] = -1
    blend = partner >= 0

    near = rows[pick]
    keypoints = dense.keypoints_px[near].copy()
    scores = dense.scores[near].copy()
    if blend.any():
        other = rows[partner[blend]]
        other_kp, other_scores = _unflipped(keypoints[blend], scores[blend] > 0, dense.keypoints_px[other],
                                            dense.scores[other])
        w = np.abs(fraction[blend])[:, None]
        both = (scores[blend] > 0) & (other_scores > 0)
        mixed_kp = np.where(both[..., None], (1.0 - w[..., None]) * keypoints[blend] + w[..., None] * other_kp,
                            keypoints[blend])
        mixed_scores = np.where(both, (1.0 - w) * scores[blend] + w * other_scores, scores[blend])
        keypoints[blend], scores[blend] = mixed_kp, mixed_scores
    out = DenseDetections(target.astype(np.int64), np.full(len(target), view, dtype=np.int64),
                          dense.det_id[near].astype(np.int64), keypoints, scores)
    used = np.union1d(frames[pick], frames[partner[blend]])
    remainder = np.where(blend, 0.0, fraction)
    remainder[np.abs(remainder) < _ON_FRAME] = 0.0
    return ViewAtTimes(out, remainder, blend, used)


def views_at_times(detections: pd.DataFrame, source_frames: Mapping[int, np.ndarray]
                   ) -> tuple[pd.DataFrame, dict[int, ViewAtTimes]]:
    """Several views of one capture at times of their own clocks (:func:`view_at_times` per view), as one table.

    Args:
        detections: canonical ``detections`` table of one sequence, each view's ``frame`` on its own clock.
        source_frames: view -> (M,) for each time asked for, the view's own frame at that time (NaN: none asked).

    Returns:
        ``(table, per_view)``: the canonical ``detections`` of those views with ``frame`` the index of the time
        (sorted by frame, view, det_id and joint; the input's dtypes), and each view's :class:`ViewAtTimes`.

    Raises:
        ValueError: the table holds more than one sequence.
    """
    sequences = detections["sequence"].unique()
    if len(sequences) > 1:
        raise ValueError(f"detections: expected one sequence, got {sorted(map(str, sequences))}")
    dense = detections_to_dense(detections)
    per_view = {v: view_at_times(dense, v, frames) for v, frames in source_frames.items()}
    parts = [dense_to_detections(at.detections, str(sequences[0])) for at in per_view.values() if len(at.detections)]
    if not parts:
        return detections.iloc[:0].copy(), per_view
    table = pd.concat(parts, ignore_index=True).astype(detections.dtypes.to_dict())
    return sort_detections(table), per_view


def _lookup(track: np.ndarray, frames: np.ndarray, want_track: np.ndarray, want_frame: np.ndarray) -> np.ndarray:
    """Index into ``track`` / ``frames`` of the detection of track ``want_track`` at ``want_frame`` (-1: none)."""
    if not len(track):
        return np.full(len(want_track), -1, dtype=np.int64)
    low = min(frames.min(), want_frame.min(initial=frames.min())) - 1
    span = max(frames.max(), want_frame.max(initial=frames.max())) - low + 2
    keys = track * span + (frames - low)
    order = np.argsort(keys, kind="stable")
    wanted = want_track * span + (want_frame - low)
    at = np.minimum(np.searchsorted(keys[order], wanted), len(keys) - 1)
    found = keys[order][at] == wanted
    return np.where(found, order[at], -1)


def _unflipped(keypoints: np.ndarray, valid: np.ndarray, other_kp: np.ndarray, other_scores: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """``other`` as it is, or left-right flipped where that puts its joints nearer to ``keypoints`` (mean distance
    of the joints both have). Shapes: (B, 23, 2) and (B, 23)."""
    def mean_distance(kp: np.ndarray, sc: np.ndarray) -> np.ndarray:
        both = valid & (sc > 0)
        dist = np.where(both, np.linalg.norm(np.nan_to_num(keypoints - kp), axis=-1), 0.0)
        return dist.sum(axis=1) / np.maximum(both.sum(axis=1), 1)

    flipped_kp, flipped_scores = other_kp[:, FLIP_INDEX], other_scores[:, FLIP_INDEX]
    flip = mean_distance(flipped_kp, flipped_scores) < mean_distance(other_kp, other_scores)
    return (np.where(flip[:, None, None], flipped_kp, other_kp),
            np.where(flip[:, None], flipped_scores, other_scores))
