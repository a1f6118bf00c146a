"""Time offsets of unsynchronised views, estimated from the people's motion alone (no camera is known yet).

Convention (``docs/capture.md``, "Unsynchronised videos"): view ``v``'s frame ``n`` is taken at reference time
``t = n / fps_v + offset_v`` seconds; view 0 is the reference, ``offset_0 = 0``. A view whose recording started
``k`` frames after view 0's (its frame 0 is view 0's frame ``k``) has ``offset_v = k / fps_0``.

How (:func:`estimate_time_offsets`):

1. per view, the people tracked frame to frame in the image, each track with its pose signal
   (:mod:`humancal.sync.signals`: joint angles and distances between joints of the lifter's 3D poses, which do not
   depend on the camera);
2. every pair of views: the tracks on a common clock (the highest frame rate), and at every lag the search window
   allows (``max_offset_s`` from view 0, so twice that between two other views) each track's best partner in the
   other view by masked normalised cross-correlation (:mod:`humancal.sync.correlation`); the lag where the
   partners agree best, refined by a parabola (a fraction of a sample), and how clearly it stands out: ``margin``
   = peak minus the best other local maximum. A pair is *clear* when its peak is at least ``min_peak`` and its
   margin at least ``min_margin``;
3. the offsets from the clear pairs by weighted least squares (weights: the margins), view 0 held at 0; a pair that
   disagrees with the solution by more than ``tolerance_frames`` is dropped (the worst first) and the rest solved
   again;
4. the fine stage (lifted signals, ``fine_samples`` > 0): each view's offset moved to the whole common-clock sample,
   within ``fine_samples`` of the least-squares one, where the lifted poses of all its used pairs agree best
   (:func:`humancal.sync.correlation.pose_distance`; the correlation's peak is broad, a pose one frame off differs
   by a frame's motion).

A view's status: ``"ok"`` when it is linked to view 0 through used pairs that each lie on a cycle of used pairs
(offset(a, b) + offset(b, c) = offset(a, c) held: its offset is cross-checked), ``"unchecked"`` when a pair that no
cycle confirms links it (two views; or a view the others barely share motion with), ``"ambiguous"`` when no clear
pair links it to view 0 (the people hardly move, or their motion repeats: a flat curve or two peaks). Neither an
unchecked nor an ambiguous offset is used: :func:`humancal.sync.capture.synchronise_views` refuses them and names
the view.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.config import Config, in_range, positive
from humancal.sync.correlation import ClockTracks, LagPeak, correlate_views, find_peak, pose_distance, resample_tracks
from humancal.sync.signals import SIGNAL_KINDS, track_signals
from humancal.tables.detections import detections_to_dense

__all__ = ["STATUSES", "SyncConfig", "PairOffset", "TimeOffsets", "estimate_time_offsets",
           "estimate_time_offsets_lifted", "per_view_fps", "tentative_offsets_s"]

log = logging.getLogger(__name__)

STATUSES: tuple[str, ...] = ("ok", "unchecked", "ambiguous")
"""A view's status in :class:`TimeOffsets` (module docstring)."""


@dataclass(frozen=True)
class SyncConfig(Config):
    """How the offsets are searched for.

    Attributes:
        max_offset_s: the largest offset of a view from view 0 searched, seconds (either sign).
        signal: the pose signal (:data:`humancal.sync.signals.SIGNAL_KINDS`): ``"lifted"`` (angles and distances of
            the lifter's 3D poses, the default: on 10 synthetic scenes, in a first version of the search, 31 % of
            the views exact to the frame against 9 % for ``"2d"`` and 18 % for ``"both"``), ``"2d"`` (measured in
            the image, no lifter) or ``"both"``.
        min_overlap_s: two tracks (one per view) that share less than this at a lag are not compared there, seconds.
        min_peak: a pair's correlation peak must reach this to be clear.
        min_margin: ... and stand this far above the best other local maximum (0.2 used no wrong view on the
            sweep of `scripts/sync_sweep.py` but refused most; 0.1 keeps the views exact to the frame).
        exclusion_s: local maxima within this of the peak are its own shoulders, seconds.
        tolerance_frames: a clear pair that disagrees with the least-squares offsets by more than this, in
            reference frames, is dropped.
        smooth_s: std of the Gaussian smoothing each track's signal over time, seconds (0: none).
        fine_samples: the fine stage tries the integer lags this many common-clock samples either side of the
            correlation's peak and keeps the one where the lifted poses agree best (0: no fine stage, the peak
            refined by a parabola instead; the ``"2d"`` signal has no lifted poses and never has one).
    """

    max_offset_s: float = field(default=2.0, metadata=positive())
    signal: str = "lifted"
    min_overlap_s: float = field(default=1.0, metadata=positive())
    min_peak: float = field(default=0.3, metadata=in_range(0, 1))
    min_margin: float = field(default=0.1, metadata=in_range(0, 1))
    exclusion_s: float = field(default=0.2, metadata=positive())
    tolerance_frames: float = field(default=0.5, metadata=positive())
    smooth_s: float = field(default=0.025, metadata=in_range(0, 10, high_open=True))
    fine_samples: int = field(default=3, metadata=in_range(0, 30, integer=True))
    joint_fine: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.signal not in SIGNAL_KINDS:
            raise ValueError(f"SyncConfig.signal must be one of {list(SIGNAL_KINDS)}, got {self.signal!r}")


@dataclass(frozen=True)
class PairOffset:
    """The correlation of one pair of views.

    Attributes:
        a, b: the views (``a < b``).
        offset_s: ``offset_b - offset_a`` at the refined peak, seconds (NaN where the correlation is undefined).
        peak: correlation at the peak (NaN where undefined).
        margin: peak minus the best other local maximum (0 where undefined).
        clear: whether the pair passed ``min_peak`` and ``min_margin``.
        used: whether it is among the pairs the offsets were solved from (clear and consistent).
    """

    a: int
    b: int
    offset_s: float
    peak: float
    margin: float
    clear: bool
    used: bool = False


@dataclass(frozen=True)
class TimeOffsets:
    """Per-view time offsets relative to view 0 (module docstring for the convention).

    Attributes:
        offset_s: (V,) seconds: view ``v``'s frame ``n`` is at reference time ``n / fps[v] + offset_s[v]``
            (NaN for an ambiguous view).
        offset_frames: (V,) the same in reference frames (view 0's): ``offset_s * fps[0]``.
        confidence: (V,) the best margin among the pairs that place the view (0 for an ambiguous one).
        status: (V,) ``"ok"``, ``"unchecked"`` or ``"ambiguous"`` (view 0, the reference: ``"ok"``).
        fps: (V,) frames per second of each view.
        pairs: every pair's correlation.
    """

    offset_s: np.ndarray
    offset_frames: np.ndarray
    confidence: np.ndarray
    status: tuple[str, ...]
    fps: np.ndarray
    pairs: tuple[PairOffset, ...] = field(default=())

    def ambiguous_views(self) -> list[int]:
        """The views whose offset must not be used."""
        return [v for v, s in enumerate(self.status) if s == "ambiguous"]


def per_view_fps(fps: float | Sequence[float], num_views: int, where: str = "fps") -> np.ndarray:
    """(V,) frames per second: one value for every view or one per view.

    Raises:
        ValueError: another count, or a value that is not a positive finite number (the message names ``where``).
    """
    values = np.atleast_1d(np.asarray(fps, dtype=float))
    if values.ndim != 1 or len(values) not in (1, num_views):
        raise ValueError(f"{where}: expected one frame rate or one per view ({num_views}), got {len(values)}")
    if not (np.isfinite(values) & (values > 0)).all():
        raise ValueError(f"{where}: expected positive frame rates, got {values.tolist()}")
    return np.broadcast_to(values, (num_views,)).copy()


def _solve(num_views: int, pairs: list[PairOffset], weights: np.ndarray) -> np.ndarray:
    """(V,) least-squares offsets from pair differences, view 0 at 0 (NaN for views no pair links to view 0)."""
    linked = _component_of(num_views, pairs, 0)
    index = {v: i for i, v in enumerate(v for v in range(1, num_views) if linked[v])}
    out = np.full(num_views, np.nan)
    out[0] = 0.0
    if not index:
        return out
    A = np.zeros((len(pairs), len(index)))
    y = np.zeros(len(pairs))
    for row, p in enumerate(pairs):
        if p.b in index:
            A[row, index[p.b]] += 1.0
        if p.a in index:
            A[row, index[p.a]] -= 1.0
        y[row] = p.offset_s
    sw = np.sqrt(weights)[:, None]
    solution = np.linalg.lstsq(A * sw, y * sw[:, 0], rcond=None)[0]
    for v, i in index.items():
        out[v] = solution[i]
    return out


def _component_of(num_views: int, pairs: list[PairOffset], view: int) -> np.ndarray:
    """(V,) whether each view is linked to ``view`` through the pairs."""
    linked = np.zeros(num_views, dtype=bool)
    linked[view] = True
    changed = True
    while changed:
        changed = False
        for p in pairs:
            if linked[p.a] != linked[p.b]:
                linked[p.a] = linked[p.b] = True
                changed = True
    return linked


def estimate_time_offsets(detections: pd.DataFrame, fps: float | Sequence[float], *, lifter=None,
                          config: SyncConfig = SyncConfig()) -> TimeOffsets:
    """Estimate each view's time offset relative to view 0 from the people's motion.

    Args:
        detections: canonical ``detections`` table of every view, each view's frames numbered on its own clock.
        fps: frames per second, one for every view or one per view (view order).
        lifter: a :class:`humancal.lifter.Lifter` (needed by the ``"lifted"`` and ``"both"`` signals).
        config: the search.

    Returns:
        The :class:`TimeOffsets` (views numbered ``0 .. max(view)``).

    Raises:
        ValueError: a view without detections, a bad ``fps``, or a lifted signal without a lifter.
    """
    dense = detections_to_dense(detections)
    V = int(dense.view.max()) + 1 if len(dense) else 0
    if V < 2:
        raise ValueError(f"detections: expected two views or more to synchronise, got {V}")
    rates = per_view_fps(fps, V)
    joints = None
    if config.signal != "2d":
        if lifter is None:
            raise ValueError(f"signal {config.signal!r} needs the lifter (lifter=)")
        from humancal.lifter import lift_detections

        joints = lift_detections(lifter, dense.keypoints_px, dense.scores).joints_cam_m
    return estimate_time_offsets_lifted(dense, rates, joints, config)


def estimate_time_offsets_lifted(dense, rates: np.ndarray, joints_m: np.ndarray | None,
                                 config: SyncConfig = SyncConfig()) -> TimeOffsets:
    """:func:`estimate_time_offsets` on dense detections already lifted.

    Args:
        dense: the capture's :class:`humancal.tables.detections.DenseDetections` (views ``0 .. V-1``).
        rates: (V,) frames per second of each view.
        joints_m: (D, 23, 3) the lifter's root-relative poses row-aligned with ``dense``, metres (None for the
            ``"2d"`` signal).
        config: the search.

    Returns:
        The :class:`TimeOffsets`.
    """
    V = len(rates)
    rate = float(rates.max())
    signals = [resample_tracks(track_signals(dense, v, config.signal, joints_m=joints_m,
                                             smooth_frames=config.smooth_s * rates[v]), float(rates[v]), rate)
               for v in range(V)]
    min_overlap = int(np.ceil(config.min_overlap_s * rate))
    exclusion = int(np.ceil(config.exclusion_s * rate))
    pairs: list[PairOffset] = []
    for a in range(V):
        for b in range(a + 1, V):
            window = config.max_offset_s * (1 if a == 0 else 2)
            max_lag = int(np.ceil(window * rate))
            lags, score = correlate_views(signals[a], signals[b], max_lag, min_overlap)
            peak = find_peak(lags, score, exclusion)
            if peak is None:
                pairs.append(PairOffset(a, b, float("nan"), float("nan"), 0.0, False))
                continue
            clear = peak.peak >= config.min_peak and peak.margin >= config.min_margin
            lag = _fine_lag(signals[a], signals[b], peak, max_lag, min_overlap, config.fine_samples)
            pairs.append(PairOffset(a, b, lag / rate, peak.peak, peak.margin, clear))
    offsets, used = _consistent_offsets(V, [p for p in pairs if p.clear], float(rates[0]), config.tolerance_frames)
    pairs = [PairOffset(p.a, p.b, p.offset_s, p.peak, p.margin, p.clear, (p.a, p.b) in used) for p in pairs]
    if config.joint_fine and config.fine_samples:
        offsets = _joint_fine(signals, [p for p in pairs if p.used], offsets, rate, min_overlap,
                              config.fine_samples)
    checked = _cross_checked(V, [p for p in pairs if p.used])
    confidence = np.zeros(V)
    for p in pairs:
        if p.used:
            for v in (p.a, p.b):
                confidence[v] = max(confidence[v], p.margin)
    status = tuple("ok" if v == 0 or (np.isfinite(offsets[v]) and checked[v])
                   else "unchecked" if np.isfinite(offsets[v]) else "ambiguous" for v in range(V))
    for v in range(V):
        log.info("view %d: time offset %+.3f s (%+.2f reference frames), %s, confidence %.2f", v, offsets[v],
                 offsets[v] * rates[0], status[v], confidence[v])
    return TimeOffsets(offsets, offsets * rates[0], confidence, status, rates, tuple(pairs))


def _fine_lag(a: ClockTracks, b: ClockTracks, peak: LagPeak, max_lag: int, min_overlap: int, fine: int) -> float:
    """A pair's lag, common-clock samples: the integer lag within ``fine`` samples of the correlation's peak where
    the lifted poses agree best (:func:`humancal.sync.correlation.pose_distance`), or the peak refined by a parabola
    where there are no lifted poses (or ``fine`` is 0, or no lag has enough shared samples)."""
    if not fine or a.pose_m is None or b.pose_m is None:
        return peak.lag
    lags = np.arange(max(peak.lag_int - fine, -max_lag), min(peak.lag_int + fine, max_lag) + 1)
    distance = pose_distance(a, b, lags, min_overlap)
    if not np.isfinite(distance).any():
        return peak.lag
    return float(lags[np.nanargmin(distance)])


def _joint_fine(signals: list[ClockTracks], used: list[PairOffset], offsets: np.ndarray, rate: float,
                min_overlap: int, fine: int) -> np.ndarray:
    """(V,) offsets, seconds, moved to whole common-clock samples where the lifted poses of all the used pairs agree
    best together: each view in turn takes the integer offset within ``fine`` samples that minimises the summed
    pose distance (:func:`humancal.sync.correlation.pose_distance`) of its used pairs at the lags the offsets
    imply, until no view moves (a view's offset rests on all its pairs at once, not one pair's own minimum)."""
    if not used or any(signals[v].pose_m is None for p in used for v in (p.a, p.b)):
        return offsets
    sample = np.where(np.isfinite(offsets), np.rint(np.nan_to_num(offsets) * rate), 0).astype(int)
    cache: dict[tuple[int, int, int], float] = {}

    def distance(p: PairOffset, lag: int) -> float:
        key = (p.a, p.b, lag)
        if key not in cache:
            span = np.arange(lag - fine, lag + fine + 1)  # evaluated a few at a time: most are needed anyway
            for k, d in zip(span, pose_distance(signals[p.a], signals[p.b], span, min_overlap)):
                cache.setdefault((p.a, p.b, int(k)), float(d))
        return cache[key]

    views = sorted({v for p in used for v in (p.a, p.b)} - {0})
    for _ in range(10):
        moved = False
        for v in views:
            mine = [p for p in used if v in (p.a, p.b)]
            costs = []
            for step in range(-fine, fine + 1):
                trial = sample.copy()
                trial[v] += step
                d = [distance(p, int(trial[p.b] - trial[p.a])) for p in mine]
                costs.append(np.nanmean(d) if np.isfinite(d).any() else np.inf)
            best = int(np.argmin(costs)) - fine
            if best and np.isfinite(costs[best + fine]):
                sample[v] += best
                moved = True
        if not moved:
            break
    return np.where(np.isfinite(offsets), sample / rate, np.nan)


def tentative_offsets_s(estimate: TimeOffsets, tolerance_frames: float = 2.0) -> np.ndarray:
    """(V,) seconds: the estimate's offsets, and for each ambiguous view a tentative one: the least-squares offsets
    of every pair whose correlation has a peak, clear or not (weights: the margins, at least 0.005), the most
    disagreeing pair dropped until all agree within ``tolerance_frames`` reference frames (NaN where no pair links
    the view to view 0). Never to be used unchecked: on the sync sweep's seated people such offsets were 0-4 frames
    off, a few tens of frames (:func:`humancal.sync.capture.synchronise_views` has the cameras check them)."""
    pairs = [p for p in estimate.pairs if np.isfinite(p.offset_s)]
    solved, _ = _consistent_offsets(len(estimate.status), pairs, float(estimate.fps[0]), tolerance_frames,
                                    min_weight=0.005)
    ambiguous = np.array([s == "ambiguous" for s in estimate.status])
    return np.where(ambiguous, solved, estimate.offset_s)


def _cross_checked(num_views: int, pairs: list[PairOffset]) -> np.ndarray:
    """(V,) whether each view's offset is cross-checked: linked to view 0 through pairs that each lie on a cycle
    of the pairs (offset(a, b) + offset(b, c) = offset(a, c) held, within the tolerance, by the consistency
    check). A pair that is a bridge (removing it cuts its views apart) rests on its own correlation alone: the
    views beyond it are only "unchecked"."""
    on_cycle = [p for k, p in enumerate(pairs)
                if _component_of(num_views, pairs[:k] + pairs[k + 1:], p.a)[p.b]]
    return _component_of(num_views, on_cycle, 0)


def _consistent_offsets(num_views: int, pairs: list[PairOffset], fps_ref: float, tolerance_frames: float,
                        min_weight: float = 0.0) -> tuple[np.ndarray, set[tuple[int, int]]]:
    """Least-squares offsets from ``pairs`` (weights: their margins, at least ``min_weight``), dropping the worst
    disagreeing pair until all agree within ``tolerance_frames``; the pairs kept."""
    kept = list(pairs)
    while True:
        offsets = _solve(num_views, kept, np.array([max(p.margin, min_weight) for p in kept]))
        if not kept:
            return offsets, set()
        residual = np.array([abs(offsets[p.b] - offsets[p.a] - p.offset_s) * fps_ref
                             if np.isfinite(offsets[p.a]) and np.isfinite(offsets[p.b]) else 0.0 for p in kept])
        worst = int(np.argmax(residual))
        if residual[worst] <= tolerance_frames:
            linked = {(p.a, p.b) for p in kept if np.isfinite(offsets[p.a]) and np.isfinite(offsets[p.b])}
            return offsets, linked
        log.info("views %d and %d: their offset %.3f s disagrees with the others' by %.1f frames: dropped",
                 kept[worst].a, kept[worst].b, kept[worst].offset_s, residual[worst])
        kept.pop(worst)
