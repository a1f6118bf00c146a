"""The detections of unsynchronised views moved to one clock: view 0's frames.

View ``v``'s frame ``n`` is taken at reference time ``t = n / fps_v + offset_v`` seconds
(:mod:`humancal.sync.offsets`); on view 0's clock that is frame ``r = (t - offset_0) * fps_0``. Two ways to put a
view on view 0's frames:

- **interpolated** (``interpolate=True``): for each frame ``m`` of view 0 the view's people at that time, blended
  from the two frames of each of its 2D tracks around it (:func:`humancal.sync.interpolate.view_at_times`). A
  detection whose track has no frame on the other side is taken from the nearest frame, and its remainder
  reported (``residual_frames``). A faster view gives one detection per track and reference frame; a slower one
  is blended for every reference frame between its frames.
- **nearest frame** (``interpolate=False``): each frame of a view goes to the nearest reference frame,
  ``round(r)``, and the remainder is reported per view (at most half a frame). Where two frames of a faster view
  land on one reference frame, the nearer in time is kept and the other dropped; a slower view leaves some
  reference frames empty.

Same frame rate and an offset of a whole number of frames: both are a renumbering and nothing else changes.
Frames that land before reference frame 0 or after view 0's last frame are dropped (counted per view).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.formats.detections.table import sort_detections
from humancal.sync.interpolate import views_at_times
from humancal.sync.offsets import per_view_fps

__all__ = ["AppliedOffsets", "apply_time_offsets"]


@dataclass(frozen=True)
class AppliedOffsets:
    """Detections on the reference clock.

    Attributes:
        detections: the canonical ``detections`` table with ``frame`` on view 0's clock (nearest frame: rows in the
            input's order, the dropped ones left out; interpolated: sorted by frame, view, det_id and joint).
        residual_frames: (V,) the largest |remainder| of a kept detection taken from its nearest frame, reference
            frames (0 for a renumbering, and for views whose every detection was interpolated).
        dropped_frames: (V,) frames with detections that went into no kept detection: outside the reference range,
            or (nearest frame) a second frame of a faster view on the same reference frame.
        interpolated: (V,) kept detections blended from two frames (0 without ``interpolate``).
    """

    detections: pd.DataFrame
    residual_frames: np.ndarray
    dropped_frames: np.ndarray
    interpolated: np.ndarray


def apply_time_offsets(detections: pd.DataFrame, offsets_s: Sequence[float] | np.ndarray,
                       fps: float | Sequence[float], *, interpolate: bool = False) -> AppliedOffsets:
    """Move every view's detections to view 0's frames.

    Args:
        detections: canonical ``detections`` table, each view's frames numbered on its own clock.
        offsets_s: (V,) time offsets, seconds (module docstring), one per view ``0 .. V-1``.
        fps: frames per second, one for every view or one per view.
        interpolate: blend each view's people between its frames at view 0's frame times (module docstring), not
            take the nearest frame.

    Returns:
        The :class:`AppliedOffsets`.

    Raises:
        ValueError: non-finite offsets, a count that does not match the views, or a bad ``fps``.
    """
    offsets = np.asarray(offsets_s, dtype=float).reshape(-1)
    V = len(offsets)
    if not np.isfinite(offsets).all():
        raise ValueError(f"offsets_s: expected finite seconds, got {offsets.tolist()}")
    views_in = np.unique(detections["view"].to_numpy())
    if len(views_in) and (views_in.min() < 0 or views_in.max() >= V):
        raise ValueError(f"offsets_s: expected one offset per view (views 0..{int(views_in.max())}), got {V}")
    rates = per_view_fps(fps, V)
    frame = detections["frame"].to_numpy(np.int64)
    view = detections["view"].to_numpy(np.int64)
    view0 = frame[view == 0]
    last = int(view0.max()) if len(view0) else -1
    if interpolate:
        return _interpolated(detections, offsets, rates, last)
    new_frame = frame.copy()
    keep = np.ones(len(frame), dtype=bool)
    residual = np.zeros(V)
    dropped = np.zeros(V, dtype=np.int64)
    for v in range(V):
        rows = view == v
        if v == 0 or not rows.any():  # view 0 is the reference clock itself
            continue
        source = np.unique(frame[rows])
        r = (source / rates[v] + offsets[v] - offsets[0]) * rates[0]
        target = np.floor(r + 0.5).astype(np.int64)
        remainder = r - target
        # one source frame per reference frame: the nearest in time (ties: the earlier frame)
        order = np.lexsort((source, np.abs(remainder), target))
        first = np.r_[True, target[order][1:] != target[order][:-1]]
        chosen = np.zeros(len(source), dtype=bool)
        chosen[order[first]] = True
        chosen &= (target >= 0) & (target <= last)
        dropped[v] = int((~chosen).sum())
        if chosen.any():
            residual[v] = float(np.abs(remainder[chosen]).max())
        lookup = np.searchsorted(source, frame[rows])
        keep[rows] = chosen[lookup]
        new_frame[rows] = target[lookup]
    out = detections.loc[keep].copy()
    out["frame"] = new_frame[keep].astype(detections["frame"].dtype)
    return AppliedOffsets(out.reset_index(drop=True), residual, dropped, np.zeros(V, dtype=np.int64))


def _interpolated(detections: pd.DataFrame, offsets: np.ndarray, rates: np.ndarray, last: int) -> AppliedOffsets:
    """:func:`apply_time_offsets` with ``interpolate``: view 0 as it is, every other view at view 0's frame times
    ``0 .. last``."""
    V = len(offsets)
    reference = np.arange(last + 1, dtype=np.float64)
    view = detections["view"].to_numpy()
    frame = detections["frame"].to_numpy()
    filmed = {v: np.unique(frame[view == v]) for v in range(1, V)}
    others, per_view = views_at_times(detections, {
        v: ((reference / rates[0] + offsets[0]) - offsets[v]) * rates[v] for v in range(1, V) if len(filmed[v])})
    residual = np.zeros(V)
    dropped = np.zeros(V, dtype=np.int64)
    interpolated = np.zeros(V, dtype=np.int64)
    for v, at in per_view.items():
        dropped[v] = len(np.setdiff1d(filmed[v], at.used_frames))
        interpolated[v] = int(at.interpolated.sum())
        if len(at.remainder_frames):
            residual[v] = float(np.abs(at.remainder_frames).max()) * rates[0] / rates[v]
    out = sort_detections(pd.concat([detections.loc[view == 0], others], ignore_index=True))
    return AppliedOffsets(out, residual, dropped, interpolated)
