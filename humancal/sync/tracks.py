"""Per-view 2D tracks: each view's detections linked frame to frame into people, with no camera known.

The motion signals of :mod:`humancal.sync.signals` need a person's consecutive detections in one view (a speed is
a difference between two frames of the same person). :func:`link_view_tracks` goes through a view's frames in order
and assigns the detections of a frame to the tracks alive then by the Hungarian method
(``scipy.optimize.linear_sum_assignment``) on the mean keypoint distance between the detection and the track's last
detection, in units of the person's size (the larger side of the keypoints' box), so that a near and a far person
are judged alike. A left-right flipped detection (a common detector error) is compared with the track both ways
and the smaller distance counts. A pair further apart than ``max_step`` sizes per frame of gap is never linked: the
detection starts a new track.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from humancal.keypoints import FLIP_INDEX
from humancal.tables.detections import DenseDetections

__all__ = ["link_view_tracks", "person_size_px"]

_UNLINKED = 1e6
"""Cost of a forbidden (gated) pair in the assignment."""


def person_size_px(keypoints_px: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Each detection's size: the larger side of the box around its detected keypoints, pixels.

    Args:
        keypoints_px: (D, 23, 2) keypoints, pixels.
        valid: (D, 23) whether each joint was detected.

    Returns:
        (D,) sizes, pixels (NaN for a detection with fewer than two joints or a zero-size box).
    """
    big = np.where(valid[..., None], keypoints_px, -np.inf).max(axis=1)
    small = np.where(valid[..., None], keypoints_px, np.inf).min(axis=1)
    with np.errstate(invalid="ignore"):
        size = (big - small).max(axis=1)
    return np.where((valid.sum(axis=1) >= 2) & (size > 0), size, np.nan)


def _pair_cost(track_kp: np.ndarray, track_valid: np.ndarray, kp: np.ndarray, valid: np.ndarray,
               size: np.ndarray) -> np.ndarray:
    """(T, D) mean distance of the common joints of each track's last detection and each new detection, in person
    sizes (the smaller of the straight and the left-right flipped comparison; inf with fewer than 3 common joints)."""
    costs = []
    for flip in (False, True):
        other_kp = kp[:, FLIP_INDEX] if flip else kp
        other_valid = valid[:, FLIP_INDEX] if flip else valid
        both = track_valid[:, None] & other_valid[None]  # (T, D, 23)
        dist = np.linalg.norm(track_kp[:, None] - other_kp[None], axis=-1)
        dist = np.where(both, dist, 0.0)
        count = both.sum(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cost = dist.sum(axis=-1) / count / size[None]
        costs.append(np.where(count >= 3, cost, np.inf))
    return np.minimum(*costs)


def link_view_tracks(dense: DenseDetections, view: int, *, max_step: float = 0.25, max_gap: int = 3) -> np.ndarray:
    """Link the detections of one view into tracks.

    Args:
        dense: the capture's detections (any views; only ``view``'s rows are linked).
        view: the view.
        max_step: the largest mean keypoint displacement between two linked detections, in person sizes per frame
            of gap (a walking person moves about 0.03 sizes per frame at 30 fps).
        max_gap: a track that has not been seen for more than this many frames is closed (a detection missed in a
            frame or two does not break it).

    Returns:
        (D,) int track id of every row of ``dense``: -1 for the rows of other views and for detections with too
        few joints to be compared; ids count up from 0 in the order the tracks start.
    """
    track_of = np.full(len(dense), -1, dtype=np.int64)
    rows = np.flatnonzero(dense.view == view)
    if not len(rows):
        return track_of
    valid = dense.valid
    size = person_size_px(dense.keypoints_px, valid)
    rows = rows[np.isfinite(size[rows])]
    frames = dense.frame[rows]
    order = np.argsort(frames, kind="stable")
    rows, frames = rows[order], frames[order]
    # open tracks: last row and last frame
    last_row: list[int] = []
    last_frame: list[int] = []
    track_ids: list[int] = []
    next_id = 0
    starts = np.flatnonzero(np.r_[True, np.diff(frames) != 0])
    stops = np.r_[starts[1:], len(frames)]
    for start, stop in zip(starts, stops):
        frame = int(frames[start])
        now = rows[start:stop]
        alive = [k for k, f in enumerate(last_frame) if frame - f <= max_gap + 1]
        linked = np.zeros(len(now), dtype=bool)
        if alive:
            prev = np.asarray([last_row[k] for k in alive])
            gap = frame - np.asarray([last_frame[k] for k in alive], dtype=float)
            scale = 0.5 * (size[prev][:, None] + size[now][None])
            cost = _pair_cost(dense.keypoints_px[prev], valid[prev], dense.keypoints_px[now], valid[now],
                              np.ones(len(now))) / scale
            allowed = cost <= max_step * gap[:, None]
            ti, di = linear_sum_assignment(np.where(allowed, cost, _UNLINKED))
            keep = allowed[ti, di]
            for t, d in zip(ti[keep], di[keep]):
                k = alive[t]
                track_of[now[d]] = track_ids[k]
                last_row[k], last_frame[k] = int(now[d]), frame
                linked[d] = True
        for d in np.flatnonzero(~linked):
            track_of[now[d]] = next_id
            track_ids.append(next_id)
            last_row.append(int(now[d]))
            last_frame.append(frame)
            next_id += 1
        # forget the tracks that can no longer be continued, so that the assignment stays small
        keep_open = [k for k, f in enumerate(last_frame) if frame - f <= max_gap + 1]
        last_row = [last_row[k] for k in keep_open]
        last_frame = [last_frame[k] for k in keep_open]
        track_ids = [track_ids[k] for k in keep_open]
    return track_of

