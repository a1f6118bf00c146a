"""Time offsets checked against cameras calibrated from the synchronised views: the errors the people's motion alone
leaves (whole frames, and the fraction of a frame) are seen as rays that miss each other.

Once the views are on one clock and calibrated, the same person's joint seen by two cameras at the same instant
gives two back-projected rays that meet (up to the detector's noise). If view ``v`` is ``k`` frames late, its frame
``n + k`` is the instant the others show at frame ``n``: its rays meet theirs best at that shift, and at shift 0
they miss each other by about ``k`` frames of the people's motion. This is the fine stage the correlation of the
lifted poses lacks (:mod:`humancal.sync.offsets`: on the synthetic sweep, the offsets it used wrongly were one frame
off), and it needs no identity across views: each detection takes its nearest partner in the other view.

How (:func:`check_offsets_with_cameras`):

1. every detection's joints as rays in the world (lens distortion undone; Plücker lines, as the association's
   geometric term, ``docs/association.md``);
2. every pair of views ``(v, u)`` and relative shift ``d`` in ``-2 K .. 2 K``: ``v``'s frame ``n + d`` against
   ``u``'s frame ``n``; each detection of either view takes its nearest partner of the other view's frame (the
   confidence-weighted mean distance between corresponding rays, metres, over at least ``min_joints`` joints),
   the distance capped at ``cap_m`` (a person the other view does not see, or a wrong partner, costs the cap, not
   more); the pair's cost at ``d`` is the mean over the detections;
3. the shifts ``s_v`` in ``-K .. K`` that minimise the mean of all pairs' costs at ``s_v - s_u``: each view in
   turn takes its best shift, the others held, until none moves (as :func:`humancal.sync.offsets` places its fine
   stage), started from the views' own frames and from each view ``u``'s best shifts of the others against it
   alone; the start that ends lowest wins (one view at a time cannot move a group: on the synthetic sweep five of
   eight views were one frame off together, the reference among the other three); the shifts are then taken
   relative to view 0's;
4. a view moves only when its best shift costs clearly less than shift 0: by at least ``min_gain`` of the cost
   at 0 (people who hardly move give a flat curve, and the offset is then left as it was, ``"flat"``);
5. a view whose *level* at its shift (the median over its pairs of views of the median nearest-partner distance:
   a person only one view sees does not raise it) is more than ``max_level_ratio`` times the views' median
   ``"disagrees"``: its rays miss the others' at every shift tried. On the synthetic sweep (``--seed 1`` of
   ``scripts/sync_sweep.py``) these were views placed tens of frames off by a consistent cycle of wrong correlation
   peaks (the calibration held their cameras), with levels 7-10 times the others' (0.15-0.20 m against 0.02 m);
   no shift within the search mends them, and they must not be used. A view whose camera the calibration itself
   says disagrees with the others (``camera_verdicts``) disagrees too: on phone rigs filming at mixed frame rates
   (``scripts/sync_sweep.py --clocks consumer``) six of ten views were placed a gait cycle off together, the
   calibration built itself around them and judged every camera disagreeing, while their levels looked fine
   (:func:`humancal.sync.capture.check_and_regroup` then looks for such a group, :mod:`humancal.sync.periods`);
6. the fraction of a frame beyond each whole shift (``sub_frame``): a camera started by hand starts between two of
   view 0's frames, and at another frame rate its frames fall anywhere between view 0's. Every pair of views whose
   cost is lowest at its relative shift ``d`` gives the vertex of the parabola through its costs at ``d - 1, d,
   d + 1``; the views' fractions are solved from those by least squares weighted by the parabolas' curvatures, view
   0's held at 0, each clipped to half a frame. On the consumer sweep (``scripts/sync_sweep.py --clocks consumer``,
   ``--seed 0``) the median error of the views used went from 0.26 to 0.10 frames;
7. each half of the capture (the instants before the median frame and from it on) searched alone (steps 3 and 6):
   a view the two halves place more than ``max_spread_frames`` apart, or one a half does not compare, is
   ``"unsure"``: the people's motion does not fix it to the frame, whatever the whole capture's curve says. When
   half or more of the views (view 0 aside) are unsure, all of them are: the motion does not fix this capture's
   clock, and the rest agreeing is no evidence. On the consumer sweep's ``--seed 0`` (and the studio sweep's
   ``--seed 1``) the views used one or more frames off were all seated people, 0.5-3.5 frames off; their halves
   were 0.84-5 frames apart, those of the views exact to the frame 0.06 apart (median; 4 of 115 above 0.75). On
   ``--seed 1`` of the consumer sweep two seated views 0.7 and 1.6 frames off had halves within 0.7 of each other,
   in a capture where five of nine views were unsure: the rule for the whole capture. And when no view besides
   view 0 is left ``"agrees"`` or ``"moved"``, the flat views are unsure too: nothing in the capture confirms the
   motion's offsets. On the consumer sweep's ``--seed 0`` (people interpolated at view 0's frame times) a capture of
   seated people had six flat views and three unsure, and four of the flat ones were used 0.2-2.2 frames off.

Convention: ``shift_frames[v] = k`` says the view's frame ``n + k`` (on the reference clock, as the detections
were synchronised) shows the reference instant ``n``; with its fraction ``sub_frame[v]``, its offset moves by
``-(k + sub_frame[v])`` reference frames (:meth:`CameraCheck.corrected_offsets_s`).
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.association.detection_geometry import DetectionGeometry, detection_geometry, ray_distances_m
from humancal.camera import CameraRig
from humancal.config import Config, at_least, in_range, positive
from humancal.keypoints import NUM_JOINTS
from humancal.tables.detections import DenseDetections

__all__ = ["CameraCheckConfig", "CameraCheck", "CHECK_STATUSES", "check_offsets_with_cameras"]

log = logging.getLogger(__name__)

CHECK_STATUSES: tuple[str, ...] = ("agrees", "moved", "flat", "unsure", "disagrees", "unchecked")
"""A view's verdict in :class:`CameraCheck`: its offset is where the cameras put it, moved to where they put it,
left as it was because the cost hardly changes with the shift, not fixed to the frame (the two halves of the capture
place it apart), wrong beyond the search (its rays miss the others' at every shift tried), or not checked (no
detections shared)."""


@dataclass(frozen=True)
class CameraCheckConfig(Config):
    """How :func:`check_offsets_with_cameras` searches.

    Attributes:
        max_shift_frames: each view's offset is searched this many reference frames either side (K).
        min_score: joints under this confidence are not used.
        min_joints: a pair of detections needs this many joints confident in both to be compared.
        cap_m: a detection's nearest-partner distance is capped at this, metres.
        min_gain: a view moves only if its best shift lowers its cost by this fraction of the cost at shift 0.
        max_level_ratio: a view whose level (module docstring) exceeds this multiple of the views' median
            disagrees.
        max_rounds: at most this many passes over the views.
        sub_frame: also estimate the fraction of a frame beyond each whole shift (module docstring, step 6; False:
            whole frames only).
        max_spread_frames: a view the two halves of the capture place further apart than this, reference frames,
            is ``"unsure"`` (module docstring, step 7).
    """

    max_shift_frames: int = field(default=3, metadata=in_range(1, 30, integer=True))
    min_score: float = field(default=0.2, metadata=in_range(0, 1))
    min_joints: int = field(default=6, metadata=in_range(1, NUM_JOINTS, integer=True))
    cap_m: float = field(default=0.2, metadata=positive())
    min_gain: float = field(default=0.01, metadata=in_range(0, 1))
    max_level_ratio: float = field(default=3.0, metadata=at_least(1.0))
    max_rounds: int = field(default=10, metadata=at_least(1, integer=True))
    sub_frame: bool = True
    max_spread_frames: float = field(default=0.75, metadata=positive())


@dataclass(frozen=True)
class CameraCheck:
    """Each view's offset error as the cameras see it.

    Attributes:
        shift_frames: (V,) int: view ``v``'s frame ``n + k`` shows reference instant ``n`` (0: its offset agrees;
            view 0: 0).
        cost_m: (V, 2K + 1) the view's mean pair cost at each shift ``-K .. K``, the others at their shifts,
            metres (NaN where no pair compares).
        level_m: (V,) the view's level at its shift: the median over its pairs of views of the median
            nearest-partner distance, metres (NaN: unchecked).
        gain: (V,) how much lower the cost is at the chosen shift than at 0, as a fraction of the cost at 0 (for
            a view that did not move: how much lower the best other shift would have been; 0 when none is).
        status: (V,) one of :data:`CHECK_STATUSES`.
        sub_frame: (V,) the fraction of a reference frame, in [-0.5, 0.5], beyond ``shift_frames`` where the
            view's rays meet the others' best (0 for view 0, and for a view ``"disagrees"`` or ``"unchecked"``).
        spread_frames: (V,) how far apart the first and the second half of the capture, each searched alone, place
            the view (whole shift and fraction, reference frames; NaN for a view ``"disagrees"`` or
            ``"unchecked"``, inf for one a half compares nowhere): a view the people's motion places to the frame
            has both halves agree.
    """

    shift_frames: np.ndarray
    cost_m: np.ndarray
    level_m: np.ndarray
    gain: np.ndarray
    status: tuple[str, ...]
    sub_frame: np.ndarray | None = None
    spread_frames: np.ndarray | None = None

    @property
    def shift(self) -> np.ndarray:
        """(V,) the whole shift plus its fraction, reference frames."""
        return self.shift_frames + (0.0 if self.sub_frame is None else self.sub_frame)

    def confirms(self, view: int) -> bool:
        """Whether the cameras vouch for the view's offset: it agrees, or moved inside the search (a view moved to
        its edge may belong further out)."""
        K = (self.cost_m.shape[1] - 1) // 2
        return self.status[view] in ("agrees", "moved") and abs(int(self.shift_frames[view])) < K

    def corrected_offsets_s(self, offsets_s: np.ndarray, reference_fps: float) -> np.ndarray:
        """(V,) the offsets, seconds, with each view's shift (whole and fraction) taken out (module docstring)."""
        return np.asarray(offsets_s, dtype=float) - self.shift / float(reference_fps)


def _pair_distances_m(geo: DetectionGeometry, weight: np.ndarray, a: np.ndarray, b: np.ndarray, min_joints: int
                      ) -> np.ndarray:
    """(P,) confidence-weighted mean distance between the corresponding joint rays of detections ``a`` and ``b``,
    metres (inf with fewer than ``min_joints`` joints used by both; ``weight``: (D, 23), 0 where not used)."""
    w = np.sqrt(weight[a] * weight[b])
    distance = np.where(w > 0, ray_distances_m(geo, a, b), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (w * distance).sum(1) / w.sum(1)
    return np.where((w > 0).sum(1) >= min_joints, mean, np.inf)


def _pair_cost(geo: DetectionGeometry, weight: np.ndarray, rows_v: np.ndarray, rows_u: np.ndarray, shift: int,
               split_frame: int, config: CameraCheckConfig) -> tuple[float, float, float, float]:
    """The cost of ``v``'s frame ``n + shift`` against ``u``'s frame ``n``: each detection's capped distance to its
    nearest partner, averaged over the detections of both views in the frames both have; the median of those
    distances; and the mean over the instants ``n`` before ``split_frame`` and from it on (NaN: none)."""
    left = pd.DataFrame({"key": geo.frame[rows_v] - shift, "a": rows_v})
    right = pd.DataFrame({"key": geo.frame[rows_u], "b": rows_u})
    pairs = left.merge(right, on="key")
    if pairs.empty:
        return float("nan"), float("nan"), float("nan"), float("nan")
    a, b = pairs["a"].to_numpy(), pairs["b"].to_numpy()
    d = np.minimum(_pair_distances_m(geo, weight, a, b, config.min_joints), config.cap_m)
    nearest_a = pd.Series(d).groupby(a).min()
    nearest_b = pd.Series(d).groupby(b).min()
    nearest = np.concatenate([nearest_a.to_numpy(), nearest_b.to_numpy()])
    instant = np.concatenate([geo.frame[nearest_a.index.to_numpy()] - shift, geo.frame[nearest_b.index.to_numpy()]])
    early = instant < split_frame
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a half without instants: NaN
        return (float(nearest.mean()), float(np.median(nearest)), float(nearest[early].mean()),
                float(nearest[~early].mean()))


def _star(pair: np.ndarray, u: int, steps: np.ndarray) -> np.ndarray:
    """(V,) shifts: view ``u`` at 0, every other view at its best shift against ``u`` alone (0 where they share
    nothing)."""
    K = (len(steps) - 1) // 2
    s = np.zeros(pair.shape[0], dtype=int)
    for v in range(pair.shape[0]):
        c = pair[v, u, steps + 2 * K]
        if v != u and np.isfinite(c).any():
            s[v] = int(steps[np.nanargmin(c)])
    return s


def _cost_of(pair: np.ndarray, s: np.ndarray, v: int, K: int) -> np.ndarray:
    """(2K + 1,) view v's mean pair cost at each shift ``-K .. K``, the others at ``s`` (a mean, not a sum: views
    of different frame rates share no frame at some shifts, and a shift must not win by comparing fewer pairs)."""
    V = len(s)
    steps = np.arange(-K, K + 1)
    others = np.arange(V) != v
    c = pair[v, others][np.arange(V - 1), steps[:, None] - s[others] + 2 * K].T
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(c, axis=0)


def _search_shifts(pair: np.ndarray, K: int, config: CameraCheckConfig) -> np.ndarray:
    """(V,) int: the shifts in ``-K .. K`` that minimise the mean pair cost (module docstring, steps 3-4), not yet
    taken relative to view 0's."""
    V = pair.shape[0]
    steps = np.arange(-K, K + 1)

    def total(s: np.ndarray) -> float:
        v, u = np.triu_indices(V, 1)
        c = pair[v, u, s[v] - s[u] + 2 * K]
        return float(np.nanmean(c)) if np.isfinite(c).any() else np.inf

    def descend(s: np.ndarray) -> np.ndarray:
        for _ in range(config.max_rounds):
            moved = False
            for v in range(V):
                cost = _cost_of(pair, s, v, K)
                if not np.isfinite(cost).any():
                    continue
                best = int(steps[np.nanargmin(cost)])
                here = cost[s[v] + K]
                if best != s[v] and cost[best + K] < here - config.min_gain * here:
                    s[v] = best
                    moved = True
            if not moved:
                break
        return s

    # from every view's own frames, and from each view u's best shifts of the others against it: the views off may
    # be most of them, the reference among the rest (one view at a time cannot move a group)
    starts = [np.zeros(V, dtype=int)] + [_star(pair, u, steps) for u in range(V)]
    s = min((descend(start) for start in starts), key=total)
    for v in range(1, V):  # a view that gains too little over its own frames keeps them
        cost = _cost_of(pair, s, v, K)
        here = cost[s[0] + K]
        if s[v] != s[0] and np.isfinite(here) and not cost[s[v] + K] < here - config.min_gain * here:
            s[v] = s[0]
    return s


def check_offsets_with_cameras(detections: DenseDetections, cameras: CameraRig,
                               config: CameraCheckConfig = CameraCheckConfig(),
                               camera_verdicts: Sequence[str] | None = None) -> CameraCheck:
    """Each view's offset error (whole frames and their fraction), from cameras calibrated on the synchronised
    detections.

    Args:
        detections: the capture's detections on the reference clock (views ``0 .. V-1``), keypoints in pixels of
            the lenses' images.
        cameras: the V cameras calibrated from them (any lens the rig has).
        config: the search.
        camera_verdicts: (V,) the calibration's own verdict on each camera (``per_view["agreement"]`` of
            :func:`humancal.calibration.estimate_extrinsics`); a camera it says ``"disagrees"`` cannot vouch for its
            view's offset: the view ``"disagrees"`` here too (None: every camera trusted).

    Returns:
        The :class:`CameraCheck` (module docstring).

    Raises:
        ValueError: detections of a view the rig does not have.
    """
    V = len(cameras)
    if len(detections) and int(detections.view.max()) >= V:
        raise ValueError(f"detections: view {int(detections.view.max())} but the rig has {V} cameras")
    K = config.max_shift_frames
    geo = detection_geometry(detections, None, cameras)
    weight = np.where((geo.scores >= config.min_score) & np.isfinite(geo.rays_world).all(-1), geo.scores, 0.0)
    rows = [np.flatnonzero(detections.view == v) for v in range(V)]
    split = int(np.median(detections.frame)) if len(detections) else 0
    relative = np.arange(-2 * K, 2 * K + 1)
    # pair[v][u][d + 2K]: v's frame n + d against u's frame n; halves[h]: the same over the instants n of half h
    pair = np.full((V, V, len(relative)), np.nan)
    median = np.full((V, V, len(relative)), np.nan)
    halves = np.full((2, V, V, len(relative)), np.nan)
    for v in range(V):
        for u in range(v + 1, V):
            for i, d in enumerate(relative):
                pair[v, u, i], median[v, u, i], halves[0, v, u, i], halves[1, v, u, i] = _pair_cost(
                    geo, weight, rows[v], rows[u], int(d), split, config)
            pair[u, v], median[u, v], halves[:, u, v] = pair[v, u, ::-1], median[v, u, ::-1], halves[:, v, u, ::-1]
    s = _search_shifts(pair, K, config)
    costs = np.stack([_cost_of(pair, s, v, K) for v in range(V)])
    with warnings.catch_warnings():  # a view no pair compares: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        level = np.array([np.nanmedian(median[v, np.arange(V) != v, s[v] - np.delete(s, v) + 2 * K])
                          for v in range(V)])
    typical = np.nanmedian(level) if np.isfinite(level).any() else np.nan
    shift = s - s[0]  # relative to view 0, the reference
    gain = np.zeros(V)
    status = []
    for v in range(V):
        cost = costs[v]
        here = cost[s[0] + K]  # the view on its own frames (as the reference)
        if not np.isfinite(here):
            status.append("unchecked" if v else "agrees")
            continue
        if level[v] > config.max_level_ratio * typical or (camera_verdicts is not None
                                                            and camera_verdicts[v] == "disagrees"):
            status.append("disagrees")
            continue
        if shift[v]:
            gain[v] = (here - cost[s[v] + K]) / here
            status.append("moved")
            continue
        others = np.delete(cost, s[0] + K)
        best_other = np.nanmin(others) if np.isfinite(others).any() else np.inf
        gain[v] = max(0.0, (here - best_other) / here) if np.isfinite(best_other) else 0.0
        status.append("agrees" if v == 0 or best_other - here >= config.min_gain * here else "flat")
    placed = [st in ("agrees", "moved", "flat") for st in status]
    fraction = _sub_frame(pair, s, placed, K) if config.sub_frame else np.zeros(V)
    # each half of the capture searched on its own: how far apart they place each view (whole shift and fraction)
    placed_by_half = []
    for h in range(2):
        s_h = _search_shifts(halves[h], K, config)
        fraction_h = _sub_frame(halves[h], s_h, placed, K) if config.sub_frame else np.zeros(V)
        placed_by_half.append(s_h - s_h[0] + fraction_h)
    spread = np.where(placed, np.abs(placed_by_half[0] - placed_by_half[1]), np.nan)
    for v in range(1, V):  # a half that compares the view nowhere cannot vouch for it either
        if placed[v] and not all(np.isfinite(_cost_of(halves[h], s, v, K)).any() for h in range(2)):
            spread[v] = np.inf
    unsure = [bool(placed[v] and v and not spread[v] <= config.max_spread_frames) for v in range(V)]
    if 2 * sum(unsure) >= max(1, sum(placed[1:])):  # the motion does not fix this capture's clock: none is trusted
        unsure = [bool(placed[v] and v) for v in range(V)]
    status = ["unsure" if unsure[v] else st for v, st in enumerate(status)]
    if not any(st in ("agrees", "moved") for st in status[1:]):  # the cameras confirm no view: nor a flat one
        status = ["unsure" if v and st == "flat" else st for v, st in enumerate(status)]
    for v in range(V):
        log.info("view %d: the cameras put its offset %+.2f frames from the estimate (%s, gain %.2f, level %.3f m, "
                 "halves %.2f frames apart)", v, -(shift[v] + fraction[v]), status[v], gain[v], level[v], spread[v])
    return CameraCheck(shift, costs, level, gain, tuple(status), fraction, spread)


def _sub_frame(pair: np.ndarray, s: np.ndarray, placed: Sequence[bool], K: int) -> np.ndarray:
    """(V,) each placed view's fraction of a frame beyond its whole shift ``s``, relative to view 0's (module
    docstring, step 6): every pair of placed views whose cost is lowest at its relative shift ``d = s_v - s_u``
    gives the vertex of the parabola through ``d - 1, d, d + 1``, ``delta``; the fractions ``f_v - f_u = delta``
    are solved by least squares weighted by the parabolas' curvatures, view 0's held at 0."""
    V = len(s)
    views = [v for v in range(1, V) if placed[v]]
    if not placed[0] or not views:
        return np.zeros(V)
    index = {v: i for i, v in enumerate(views)}
    rows, rhs, weights = [], [], []
    for v in range(V):
        for u in range(v + 1, V):
            if not (placed[v] and placed[u]):
                continue
            d = int(s[v] - s[u]) + 2 * K
            if d < 1 or d > 4 * K - 1:
                continue
            before, here, after = pair[v, u, d - 1:d + 2]
            curvature = before - 2 * here + after
            if not (np.isfinite(curvature) and curvature > 0 and here <= min(before, after)):
                continue
            row = np.zeros(len(views))
            if v in index:
                row[index[v]] += 1.0
            if u in index:
                row[index[u]] -= 1.0
            rows.append(row)
            rhs.append(0.5 * (before - after) / curvature)
            weights.append(curvature)
    out = np.zeros(V)
    if not rows:
        return out
    A, y, w = np.array(rows), np.array(rhs), np.sqrt(np.array(weights))
    solved = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)[0]
    reached = np.abs(A).sum(0) > 0  # a view no usable pair compares keeps its whole shift
    for v, i in index.items():
        if reached[i]:
            out[v] = float(np.clip(solved[i], -0.5, 0.5))
    return out
