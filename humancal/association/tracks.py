"""Tracks over time: the skeletons of each frame's clusters chained into people.

:func:`build_tracks` goes frame by frame: the clusters of a frame are assigned to the tracks by the Hungarian method
on the median 3D joint distance to each track's predicted skeleton (its last skeleton moved on by its velocity),
gated by ``assign_distance_m``; the tracks seen in the previous frame choose first, the lost ones
(re-identification after an occlusion or after the person left the views) take what is left, within the distance
the person may have walked meanwhile and only with the track's bone lengths. A cluster that matches no track starts
one (births); a track unseen for longer than ``reid_window_s`` is closed (deaths).

:func:`keep_tracks` then rejects the short tracks, stitches a track that starts after another one ended into it
(the person came back later than the re-identification window), or, with ``num_people`` given, merges the
surplus tracks into tracks they never overlap in time with; finally the people are numbered by first appearance.
"""

from __future__ import annotations

import logging
import warnings
import numpy as np
from scipy.optimize import linear_sum_assignment

from humancal.association.tracking_config import TrackingConfig
from humancal.keypoints import JOINT_INDEX, LIMB_INDEX

__all__ = ["build_tracks", "keep_tracks"]

logger = logging.getLogger("humancal.association.tracking")  # the log of the association, as before

_BODY_BONES = np.array(LIMB_INDEX[:12])
"""Arms, legs, shoulder and hip widths, torso sides: the bones whose lengths say who a person is."""
_HIPS = np.array([JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]])
_MIN_JOINTS = 3
"""A skeleton needs this many triangulated joints to be tracked, and a cluster this many joints in common with a
track to be compared with it."""
_PREDICTION_FRAMES = 5
"""A lost track's skeleton is extrapolated by its velocity for at most this many frames (people stop)."""


def _bone_lengths(joints: np.ndarray) -> np.ndarray:
    """(..., B) lengths of the body bones (NaN where a joint is missing), metres."""
    return np.linalg.norm(joints[..., _BODY_BONES[:, 0], :] - joints[..., _BODY_BONES[:, 1], :], axis=-1)


def _bone_mismatch(a: np.ndarray, b: np.ndarray) -> float:
    """Median relative difference of two (B,) bone-length vectors (0 when they share no bone)."""
    ok = np.isfinite(a) & np.isfinite(b) & (b > 0)
    return float(np.median(np.abs(a[ok] - b[ok]) / b[ok])) if ok.any() else 0.0


class _Track:
    """A track being built: its last skeleton, velocity and the skeleton rows it took."""

    def __init__(self, index: int, frame: int, row: int, joints: np.ndarray, centre: np.ndarray):
        self.index = index
        self.last = frame
        self.joints = joints.copy()
        self.centre = centre
        self.velocity = np.zeros(3)
        self.rows = [row]

    def predicted(self, frame: int) -> np.ndarray:
        return self.joints + self.velocity * min(frame - self.last, _PREDICTION_FRAMES)

    def update(self, frame: int, row: int, joints: np.ndarray, centre: np.ndarray) -> None:
        if np.isfinite(centre).all():
            if np.isfinite(self.centre).all():
                step = (centre - self.centre) / (frame - self.last)
                self.velocity = step if len(self.rows) == 1 else 0.5 * (self.velocity + step)
            self.centre = centre
        ok = np.isfinite(joints[:, 0])
        self.joints[ok] = joints[ok]
        self.last = frame
        self.rows.append(row)


def _centres(joints: np.ndarray) -> np.ndarray:
    """(S, 3) hip midpoints, or the mean of the known joints where a hip is missing (NaN without any)."""
    known = np.isfinite(joints).all(-1)
    with np.errstate(invalid="ignore"):
        mean = np.where(known[..., None], joints, 0.0).sum(1) / known.sum(1)[:, None]
    hips = joints[:, _HIPS].mean(1)
    return np.where(np.isfinite(hips).all(-1, keepdims=True), hips, mean)


def _joint_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T, S) median distance over the joints both (T, 23, 3) and (S, 23, 3) know (inf below ``_MIN_JOINTS``):
    a few wrong joints (a detection of someone else in the cluster, a flip) do not move it."""
    d = np.linalg.norm(a[:, None] - b[None], axis=-1)
    n = np.isfinite(d).sum(-1)
    ordered = np.sort(np.where(np.isfinite(d), d, np.inf), axis=-1)  # missing joints last
    lower = np.take_along_axis(ordered, np.maximum(n - 1, 0)[..., None] // 2, -1)[..., 0]
    upper = np.take_along_axis(ordered, (n // 2)[..., None], -1)[..., 0] if d.shape[-1] else lower
    median = 0.5 * (lower + np.where(n % 2 == 0, upper, lower))
    return np.where(n >= _MIN_JOINTS, median, np.inf)


def build_tracks(frames: np.ndarray, joints: np.ndarray, views: np.ndarray, config: TrackingConfig) -> np.ndarray:
    """(S,) track of every skeleton (``frames`` sorted), -1 where none took it."""
    window = config.reid_window_s * config.fps
    track_of = np.full(len(frames), -1, np.int64)
    tracks: list[_Track] = []
    trackable = np.isfinite(joints).all(-1).sum(-1) >= _MIN_JOINTS
    centres, bones = _centres(joints), _bone_lengths(joints)
    if len(frames) == 0:
        return track_of
    starts = np.flatnonzero(np.r_[True, np.diff(frames) > 0, True])
    for lo, hi in zip(starts[:-1], starts[1:]):
        f = int(frames[lo])
        rows = lo + np.flatnonzero(trackable[lo:hi])
        alive = [t for t in tracks if f - t.last <= window + 1]
        if alive and len(rows):
            gap = np.array([f - t.last for t in alive], dtype=np.float64)
            distance = _joint_distance(np.stack([t.predicted(f) for t in alive]), joints[rows])
            gate = config.assign_distance_m + config.reid_speed_mps * (gap - 1.0) / config.fps
            cost = distance / gate[:, None]
            for i in np.flatnonzero(gap > 1):  # re-identification: the same body
                seen = bones[alive[i].rows[-30:]]
                body = np.full(seen.shape[1:], np.nan)  # a bone never seen stays NaN
                measured = np.isfinite(seen).any(0)
                body[measured] = np.nanmedian(seen[:, measured], axis=0)
                for j in np.flatnonzero(cost[i] <= 1.0):
                    if _bone_mismatch(bones[rows[j]], body) > config.bone_tolerance:
                        cost[i, j] = np.inf
            # Cascade: the tracks seen in the previous frame choose first; the lost ones (re-identification) only
            # take what is left, so that a person walking on is never taken by a lost track nearby.
            for tier in (np.flatnonzero(gap <= 1), np.flatnonzero(gap > 1)):
                free = np.flatnonzero(track_of[rows] < 0)
                if len(tier) == 0 or len(free) == 0:
                    continue
                sub = cost[np.ix_(tier, free)]
                ti, si = linear_sum_assignment(np.where(sub <= 1.0, sub, 1e6))
                for i, j in zip(ti, si):
                    if sub[i, j] <= 1.0:
                        row = rows[free[j]]
                        alive[tier[i]].update(f, row, joints[row], centres[row])
                        track_of[row] = alive[tier[i]].index
        for j in rows[track_of[rows] < 0]:
            if views[j] >= config.min_views:
                tracks.append(_Track(len(tracks), f, j, joints[j], centres[j]))
                track_of[j] = tracks[-1].index
    return track_of


def keep_tracks(track_of: np.ndarray, frames: np.ndarray, joints: np.ndarray, config: TrackingConfig,
                 warnings: list[str]) -> np.ndarray:
    """(S,) final person of every skeleton (0..P-1 by first appearance, -1: rejected): short tracks rejected,
    then (``num_people`` given) surplus tracks merged or dropped."""
    track_of = track_of.copy()
    ids, length = np.unique(track_of[track_of >= 0], return_counts=True)
    min_frames = max(1, int(np.ceil(config.min_track_s * config.fps - 1e-9)))
    for t in ids[length < min_frames]:
        track_of[track_of == t] = -1
    kept = np.unique(track_of[track_of >= 0])
    if config.num_people is None and config.stitch_window_s > 0:
        track_of = _stitch_tracks(track_of, frames, joints, config)
    elif config.num_people is not None and len(kept) > config.num_people:
        track_of = _merge_surplus(track_of, frames, joints, config)
    return _number_by_first_frame(track_of, frames)


def _stitch_tracks(track_of: np.ndarray, frames: np.ndarray, joints: np.ndarray, config: TrackingConfig) -> np.ndarray:
    """Join a track that starts after another one ended (within ``stitch_window_s``) into it when the two share
    bone lengths (within ``bone_tolerance``) and the person could have walked from one end to the other
    (``assign_distance_m`` + ``reid_speed_mps`` x gap): a person back after longer than the re-identification
    window keeps their id. Tracks are taken in order of their first frame; each joins the nearest such track."""
    track_of = track_of.copy()
    ids = np.unique(track_of[track_of >= 0])
    if len(ids) < 2:
        return track_of
    rows_of = {t: np.flatnonzero(track_of == t) for t in ids}
    with warnings.catch_warnings():  # a bone never measured in a track stays NaN (not compared)
        warnings.simplefilter("ignore", RuntimeWarning)
        bones = {t: np.nanmedian(_bone_lengths(joints[r]), axis=0) for t, r in rows_of.items()}
    order = sorted(ids, key=lambda t: frames[rows_of[t][0]])
    window = config.stitch_window_s * config.fps
    for late in order:
        mine = rows_of[late]
        start = frames[mine[0]]
        best, best_cost = None, np.inf
        for early in order:
            theirs = rows_of.get(early)
            if early == late or theirs is None or len(theirs) == 0:
                continue
            end = frames[theirs[-1]]
            gap = start - end
            if gap <= 0 or gap > window:
                continue
            if _bone_mismatch(bones[late], bones[early]) > config.bone_tolerance:
                continue
            distance = _joint_distance(joints[theirs[-1]][None], joints[mine[0]][None])[0, 0]
            cost = distance / (config.assign_distance_m + config.reid_speed_mps * (gap - 1) / config.fps)
            if cost <= 1.0 and cost < best_cost:
                best, best_cost = early, cost
        if best is not None:
            logger.info("associate: track %d (from frame %d) continues track %d", late, start, best)
            track_of[mine] = best
            rows_of[best] = np.sort(np.concatenate([rows_of[best], mine]))
            rows_of[late] = np.zeros(0, np.int64)
    return track_of


def _merge_surplus(track_of: np.ndarray, frames: np.ndarray, joints: np.ndarray, config: TrackingConfig) -> np.ndarray:
    """Bring the tracks down to ``num_people``: the shortest merges into the track it never overlaps in time with,
    with the same bone lengths (within ``bone_tolerance``) and nearest at the junction; dropped without one."""
    track_of = track_of.copy()
    while True:
        ids, length = np.unique(track_of[track_of >= 0], return_counts=True)
        if len(ids) <= config.num_people:
            return track_of
        short = ids[np.argmin(length)]
        mine = np.flatnonzero(track_of == short)
        body = np.nanmedian(_bone_lengths(joints[mine]), axis=0)
        best, best_cost = -1, np.inf
        for other in ids[ids != short]:
            theirs = np.flatnonzero(track_of == other)
            if np.intersect1d(frames[mine], frames[theirs]).size:
                continue
            if _bone_mismatch(body, np.nanmedian(_bone_lengths(joints[theirs]), axis=0)) > config.bone_tolerance:
                continue
            # the nearest skeletons in time on both sides of the junction
            gap = np.abs(frames[mine][:, None] - frames[theirs][None, :])
            i, j = np.unravel_index(np.argmin(gap), gap.shape)
            distance = _joint_distance(joints[mine[i]][None], joints[theirs[j]][None])[0, 0]
            cost = distance / (config.assign_distance_m + config.reid_speed_mps * (gap[i, j] - 1) / config.fps)
            if cost < best_cost:
                best, best_cost = other, cost
        if best >= 0:
            logger.info("associate: num_people=%d: track %d (%d frames) merged into track %d", config.num_people,
                        short, len(mine), best)
            track_of[mine] = best
        else:
            logger.info("associate: num_people=%d: track %d (%d frames) dropped (no track to merge it into)",
                        config.num_people, short, len(mine))
            track_of[mine] = -1


def _number_by_first_frame(track_of: np.ndarray, frames: np.ndarray) -> np.ndarray:
    ids = np.unique(track_of[track_of >= 0])
    first = np.array([frames[track_of == t].min() for t in ids])
    renumber = np.full(int(track_of.max()) + 1 if len(ids) else 0, -1, np.int64)
    renumber[ids[np.lexsort((ids, first))]] = np.arange(len(ids))
    return np.where(track_of >= 0, renumber[np.maximum(track_of, 0)] if len(ids) else -1, -1)

