"""Time offsets checked against cameras calibrated from the synchronised views: the whole-frame errors the people's
motion alone leaves are seen as rays that miss each other.

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
   calibration built itself around them and judged every camera disagreeing, while their levels looked fine.

Convention: ``shift_frames[v] = k`` says the view's frame ``n + k`` (on the reference clock, as the detections
were synchronised) shows the reference instant ``n``: its offset moves by ``-k`` reference frames
(:meth:`CameraCheck.corrected_offsets_s`).
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

CHECK_STATUSES: tuple[str, ...] = ("agrees", "moved", "flat", "disagrees", "unchecked")
"""A view's verdict in :class:`CameraCheck`: its offset is where the cameras put it, moved to where they put it,
left as it was because the cost hardly changes with the shift, wrong beyond the search (its rays miss the others'
at every shift tried), or not checked (no detections shared)."""


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
    """

    max_shift_frames: int = field(default=3, metadata=in_range(1, 30, integer=True))
    min_score: float = field(default=0.2, metadata=in_range(0, 1))
    min_joints: int = field(default=6, metadata=in_range(1, NUM_JOINTS, integer=True))
    cap_m: float = field(default=0.2, metadata=positive())
    min_gain: float = field(default=0.01, metadata=in_range(0, 1))
    max_level_ratio: float = field(default=3.0, metadata=at_least(1.0))
    max_rounds: int = field(default=10, metadata=at_least(1, integer=True))


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
    """

    shift_frames: np.ndarray
    cost_m: np.ndarray
    level_m: np.ndarray
    gain: np.ndarray
    status: tuple[str, ...]

    def corrected_offsets_s(self, offsets_s: np.ndarray, reference_fps: float) -> np.ndarray:
        """(V,) the offsets, seconds, with each view's shift taken out (module docstring)."""
        return np.asarray(offsets_s, dtype=float) - self.shift_frames / float(reference_fps)


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
               config: CameraCheckConfig) -> tuple[float, float]:
    """The cost of ``v``'s frame ``n + shift`` against ``u``'s frame ``n``: each detection's capped distance to its
    nearest partner, averaged over the detections of both views in the frames both have, and the median of those
    distances (NaN, NaN: none)."""
    left = pd.DataFrame({"key": geo.frame[rows_v] - shift, "a": rows_v})
    right = pd.DataFrame({"key": geo.frame[rows_u], "b": rows_u})
    pairs = left.merge(right, on="key")
    if pairs.empty:
        return float("nan"), float("nan")
    a, b = pairs["a"].to_numpy(), pairs["b"].to_numpy()
    d = np.minimum(_pair_distances_m(geo, weight, a, b, config.min_joints), config.cap_m)
    nearest_a = pd.Series(d).groupby(a).min().to_numpy()
    nearest_b = pd.Series(d).groupby(b).min().to_numpy()
    nearest = np.concatenate([nearest_a, nearest_b])
    return float(nearest.mean()), float(np.median(nearest))


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


def check_offsets_with_cameras(detections: DenseDetections, cameras: CameraRig,
                               config: CameraCheckConfig = CameraCheckConfig(),
                               camera_verdicts: Sequence[str] | None = None) -> CameraCheck:
    """Each view's whole-frame offset error, from cameras calibrated on the synchronised detections.

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
    relative = np.arange(-2 * K, 2 * K + 1)
    # pair[v][u][d + 2K]: v's frame n + d against u's frame n
    pair = np.full((V, V, len(relative)), np.nan)
    median = np.full((V, V, len(relative)), np.nan)
    for v in range(V):
        for u in range(v + 1, V):
            for i, d in enumerate(relative):
                pair[v, u, i], median[v, u, i] = _pair_cost(geo, weight, rows[v], rows[u], int(d), config)
            pair[u, v], median[u, v] = pair[v, u, ::-1], median[v, u, ::-1]
    steps = np.arange(-K, K + 1)

    def cost_of(s: np.ndarray, v: int) -> np.ndarray:
        """(2K + 1,) view v's mean pair cost at each shift, the others at ``s`` (a mean, not a sum: views of
        different frame rates share no frame at some shifts, and a shift must not win by comparing fewer pairs)."""
        others = np.arange(V) != v
        c = pair[v, others][np.arange(V - 1), steps[:, None] - s[others] + 2 * K].T
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmean(c, axis=0)

    def total(s: np.ndarray) -> float:
        v, u = np.triu_indices(V, 1)
        c = pair[v, u, s[v] - s[u] + 2 * K]
        return float(np.nanmean(c)) if np.isfinite(c).any() else np.inf

    def descend(s: np.ndarray) -> np.ndarray:
        for _ in range(config.max_rounds):
            moved = False
            for v in range(V):
                cost = cost_of(s, v)
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
        cost = cost_of(s, v)
        here = cost[s[0] + K]
        if s[v] != s[0] and np.isfinite(here) and not cost[s[v] + K] < here - config.min_gain * here:
            s[v] = s[0]
    costs = np.stack([cost_of(s, v) for v in range(V)])
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
    for v in range(V):
        log.info("view %d: the cameras put its offset %+d frames from the estimate (%s, gain %.2f, level %.3f m)",
                 v, -shift[v], status[v], gain[v], level[v])
    return CameraCheck(shift, costs, level, gain, tuple(status))
