"""Views placed a whole period of the people's motion off together, found by the epipolar geometry of each pair of
views and moved back.

A walk repeats every gait cycle (about a second), so the correlation of the people's motion
(:mod:`humancal.sync.offsets`) has a second peak one period from the true one in every pair of views. When most
pairs across two groups of views take their wrong peak, the least squares place the offsets consistently and a
whole group a period off: the pairs inside each group agree, and so do the wrong ones across. The cameras then
calibrated from the people on that clock disagree with each other everywhere (a person seen a stride apart in time
is in two places), which is how :func:`humancal.sync.capture.calibrate_and_check` sees it, but nothing in the
calibration says which views form the group.

The pairs' two-view geometry says it without cameras. At the right relative offset the same person's joints in
two views at the same instant are images of the same 3D points, so one fundamental matrix explains many of them; a
period off, each person has moved by their own stride and turned, and far fewer fit one. Every detection of one
view is paired with every detection of the other in the same frame (no identity across views is needed: the wrong
pairings are RANSAC's outliers, the same share at every shift), and the pair's *support* at a shift is the fraction
of the pairings' joints RANSAC keeps as inliers. The fundamental matrix needs no intrinsics (those estimated from
upright people alone can be far off before the views are solved together) and absorbs a phone's mild distortion
within the threshold.

How (:func:`regroup_by_period`):

1. the period: the pairs whose correlation's peak (clear or not: an ambiguous view's tentative offset rests on
   unclear ones) misses the offsets by ``min_period_frames`` or more took another peak, about one, two or three
   periods away. Each miss is tried as the period; the one that explains the most misses (within
   ``period_tolerance_frames`` of a multiple), the longest of those, wins, and the period is the median of the
   misses it explains, each divided by its multiple (no miss: nothing to search; a lone miss is the period);
2. every view's detections on the reference clock at its offset plus ``d`` periods, ``d`` in ``-2 .. 2``
   (view 0 held), and each pair's support at every relative shift ``d``;
3. the whole periods ``k_v`` in ``-1 .. 1`` (``k_0 = 0``) that maximise the summed support of all pairs at
   ``k_b - k_a``: every labelling tried when there are few views, else each view in turn moved to its best until
   none moves;
4. the offsets moved by ``k_v`` periods. They are then checked by cameras calibrated on the new clock, like the
   first ones: this search proposes, the check decides.

On the phone sweep's two-person walking capture that first placed six of ten views a gait cycle off
(``scripts/sync_sweep.py --clocks consumer --with-cameras``, ``--seed 0``, scene 2), the support at the true
offsets was the highest of the three shifts (true, and a period either way) in 41 of 45 pairs (an essential matrix
with the true intrinsics: 45 of 45).
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field

import cv2
import numpy as np
import pandas as pd

from humancal.config import Config, at_least, in_range, positive
from humancal.sync.apply import apply_time_offsets
from humancal.sync.offsets import TimeOffsets
from humancal.tables.detections import DenseDetections, detections_to_dense

__all__ = ["PeriodConfig", "PeriodSearch", "misplaced_period_s", "pair_support", "regroup_by_period"]

log = logging.getLogger(__name__)

SHIFTS = np.arange(-2, 3)
"""The relative shifts of a pair of views, whole periods, at which its support is measured."""


@dataclass(frozen=True)
class PeriodConfig(Config):
    """How :func:`regroup_by_period` searches.

    Attributes:
        min_period_frames: a clear pair that disagrees with the offsets by at least this many reference frames took
            another peak of its correlation (a period away).
        period_tolerance_frames: a miss within this many reference frames of one to three periods is explained by
            that period.
        min_score: joints under this confidence are not paired.
        threshold_px: RANSAC's inlier threshold (distance to the epipolar line), pixels.
        max_iterations: RANSAC's iterations at most.
        max_points: at most this many pairs of joints per pair of views and shift (a seeded sample).
        min_points: a pair of views with fewer pairs of joints at a shift has no support there.
        max_exhaustive_views: with at most this many views every labelling is tried (3 ** (V - 1)); with more, the
            views are moved one at a time.
        seed: the sample's and RANSAC's seed.
    """

    min_period_frames: float = field(default=5.0, metadata=positive())
    period_tolerance_frames: float = field(default=2.0, metadata=positive())
    min_score: float = field(default=0.3, metadata=in_range(0, 1))
    threshold_px: float = field(default=4.0, metadata=positive())
    max_iterations: int = field(default=2000, metadata=at_least(1, integer=True))
    max_points: int = field(default=3000, metadata=at_least(20, integer=True))
    min_points: int = field(default=50, metadata=at_least(8, integer=True))
    max_exhaustive_views: int = field(default=11, metadata=at_least(2, integer=True))
    seed: int = 0


@dataclass(frozen=True)
class PeriodSearch:
    """What :func:`regroup_by_period` found.

    Attributes:
        period_s: the period searched, seconds.
        shift_periods: (V,) whole periods each view's offset moves by (view 0: 0).
        offset_s: (V,) the offsets moved, seconds.
        support: (V, V, 5) each pair's support (``a < b``: the fraction of its pairs of joints a fundamental matrix
            explains) at relative shifts of -2 .. 2 periods of ``b`` against ``a``; NaN where too few were paired.
        gain: the summed support of the labelling found less that of the offsets as they were (0: none moved).
    """

    period_s: float
    shift_periods: np.ndarray
    offset_s: np.ndarray
    support: np.ndarray
    gain: float

    @property
    def moved(self) -> list[int]:
        """The views whose offset moved."""
        return [int(v) for v in np.flatnonzero(self.shift_periods)]


def misplaced_period_s(estimate: TimeOffsets, offsets_s: np.ndarray, config: PeriodConfig = PeriodConfig()
                       ) -> float | None:
    """The period, seconds, by whole numbers of which the pairs of views miss ``offsets_s`` (module docstring,
    step 1); None when no pair misses by ``min_period_frames`` reference frames or more, or when two or more do and
    none of them explains another."""
    fps_ref = float(estimate.fps[0])
    misses = np.array([abs(p.offset_s - (offsets_s[p.b] - offsets_s[p.a])) for p in estimate.pairs
                       if np.isfinite(p.offset_s) and np.isfinite(offsets_s[p.a]) and np.isfinite(offsets_s[p.b])])
    misses = misses[misses * fps_ref >= config.min_period_frames]
    if not len(misses):
        return None
    tolerance = config.period_tolerance_frames / fps_ref

    def multiples(period: float) -> np.ndarray:
        k = np.rint(misses / period)
        return np.where((k >= 1) & (k <= 3) & (np.abs(misses - k * period) <= tolerance), k, 0)

    explained = np.array([np.count_nonzero(multiples(m)) for m in misses])
    # the candidate explaining the most misses; of those, the longest (half a period explains as much)
    best = max(range(len(misses)), key=lambda i: (explained[i], misses[i]))
    if explained[best] < min(2, len(misses)):
        return None
    k = multiples(misses[best])
    return float(np.median(misses[k > 0] / k[k > 0]))


def pair_support(dense_a: DenseDetections, rows_a: np.ndarray, dense_b: DenseDetections, rows_b: np.ndarray,
                 config: PeriodConfig = PeriodConfig()) -> float:
    """The fraction of the pairs of joints of two views a fundamental matrix explains (module docstring).

    Args:
        dense_a, dense_b: detections on the reference clock (may be the same table).
        rows_a, rows_b: the rows of each view in its table.
        config: the pairing and RANSAC.

    Returns:
        The inlier fraction, or NaN when fewer than ``min_points`` pairs of joints share a frame.
    """
    left = pd.DataFrame({"frame": dense_a.frame[rows_a], "a": rows_a})
    right = pd.DataFrame({"frame": dense_b.frame[rows_b], "b": rows_b})
    pairs = left.merge(right, on="frame")
    if pairs.empty:
        return float("nan")
    ia, ib = pairs["a"].to_numpy(), pairs["b"].to_numpy()
    both = (dense_a.scores[ia] >= config.min_score) & (dense_b.scores[ib] >= config.min_score)
    det, joint = np.nonzero(both)
    if len(det) < config.min_points:
        return float("nan")
    if len(det) > config.max_points:
        keep = np.random.default_rng(config.seed).choice(len(det), config.max_points, replace=False)
        det, joint = det[keep], joint[keep]
    points_a = dense_a.keypoints_px[ia[det], joint].astype(np.float64)
    points_b = dense_b.keypoints_px[ib[det], joint].astype(np.float64)
    cv2.setRNGSeed(config.seed)
    _, inliers = cv2.findFundamentalMat(points_a, points_b, cv2.FM_RANSAC, config.threshold_px, 0.999,
                                        config.max_iterations)
    return float(inliers.mean()) if inliers is not None else 0.0


def regroup_by_period(detections: pd.DataFrame, offsets_s: np.ndarray, rates: np.ndarray, period_s: float,
                      config: PeriodConfig = PeriodConfig()) -> PeriodSearch:
    """Move groups of views whole periods where the pairs' epipolar geometry supports them best (module docstring,
    steps 2-4).

    Args:
        detections: canonical ``detections`` table, each view on its own frames (views ``0 .. V-1``).
        offsets_s: (V,) the offsets as estimated, seconds (view 0: 0).
        rates: (V,) frames per second of each view.
        period_s: the period, seconds (:func:`misplaced_period_s`).
        config: the search.

    Returns:
        The :class:`PeriodSearch`.
    """
    offsets_s = np.asarray(offsets_s, dtype=float)
    V = len(offsets_s)
    moved_by = np.arange(V) > 0
    tables = {}
    for d in SHIFTS:
        dense = detections_to_dense(apply_time_offsets(detections, offsets_s + d * period_s * moved_by,
                                                       rates).detections)
        tables[int(d)] = (dense, [np.flatnonzero(dense.view == v) for v in range(V)])
    support = np.full((V, V, len(SHIFTS)), np.nan)
    dense_a, rows_a = tables[0]  # view a at its offset, view b at its offset plus d periods
    for a, b in itertools.combinations(range(V), 2):
        for i, d in enumerate(SHIFTS):
            dense_b, rows_b = tables[int(d)]
            support[a, b, i] = pair_support(dense_a, rows_a[a], dense_b, rows_b[b], config)
    labels = _best_labels(support, V, config.max_exhaustive_views)
    score = _scores(support, labels[None])[0]
    gain = float(score - _scores(support, np.zeros((1, V), dtype=int))[0])
    for a, b in itertools.combinations(range(V), 2):
        log.debug("views %d and %d: support at -2..2 periods %s", a, b, np.round(support[a, b], 3).tolist())
    return PeriodSearch(period_s, labels, offsets_s + labels * period_s, support, gain)


def _scores(support: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(N,) the summed support of the pairs at the relative shifts of (N, V) labellings (a pair without support at
    a shift adds its lowest support)."""
    V = support.shape[0]
    a, b = np.triu_indices(V, 1)
    filled = support[a, b]  # (P, 5)
    floor = np.nanmin(np.where(np.isfinite(filled).any(1, keepdims=True), filled, 0.0), axis=1, keepdims=True)
    filled = np.where(np.isfinite(filled), filled, floor)
    d = labels[:, b] - labels[:, a] + SHIFTS.max()  # (N, P) column of each pair's shift
    return filled[np.arange(len(a))[None], d].sum(1)


def _best_labels(support: np.ndarray, V: int, max_exhaustive_views: int) -> np.ndarray:
    """(V,) the labelling in -1 .. 1 (view 0 at 0) of the highest summed support (module docstring, step 3)."""
    if V <= max_exhaustive_views:
        rest = np.array(list(itertools.product((-1, 0, 1), repeat=V - 1)), dtype=int).reshape(-1, V - 1)
        labels = np.concatenate([np.zeros((len(rest), 1), dtype=int), rest], axis=1)
        scores = _scores(support, labels)
        # ties (a pair without support anywhere) go to the labelling that moves fewest views
        best = np.lexsort((np.abs(labels).sum(1), -scores))[0]
        return labels[best]
    labels = np.zeros(V, dtype=int)
    for _ in range(10):
        changed = False
        for v in range(1, V):
            trials = np.repeat(labels[None], 3, axis=0)
            trials[:, v] = (-1, 0, 1)
            scores = _scores(support, trials)
            best = int(trials[np.argmax(scores), v])
            if best != labels[v] and scores.max() > _scores(support, labels[None])[0]:
                labels[v], changed = best, True
        if not changed:
            break
    return labels
