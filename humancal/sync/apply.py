"""The detections of unsynchronised views moved to one clock: view 0's frames.

View ``v``'s frame ``n`` is taken at reference time ``t = n / fps_v + offset_v`` seconds
(:mod:`humancal.sync.offsets`); on view 0's clock that is frame ``r = (t - offset_0) * fps_0``. Each frame of a view
goes to the nearest reference frame, ``round(r)``:

- same frame rate, an offset of a whole number of frames: a renumbering, nothing else changes;
- a fraction of a frame left over (an estimated offset, or a given one in seconds): the frames are rounded to the
  nearest reference frame, and the remainder is reported per view (``residual_frames``; at most half a frame). The
  method then treats the views as in sync; a bundle adjustment with interpolated detections could use the
  remainders later, none does today;
- another frame rate: each frame goes to its nearest reference frame (no interpolation); where two frames of a
  faster view land on one reference frame, the nearer in time is kept and the other dropped; a slower view leaves
  some reference frames empty.

Frames that land before reference frame 0 or after view 0's last frame are dropped (counted per view).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.sync.offsets import per_view_fps

__all__ = ["AppliedOffsets", "apply_time_offsets"]


@dataclass(frozen=True)
class AppliedOffsets:
    """Detections on the reference clock.

    Attributes:
        detections: the canonical ``detections`` table with ``frame`` on view 0's clock (rows in the input's order,
            the dropped ones left out).
        residual_frames: (V,) the largest |remainder| of a kept frame after rounding, reference frames (0 for a
            renumbering).
        dropped_frames: (V,) frames with detections dropped: outside the reference range, or a second frame of a
            faster view on the same reference frame.
    """

    detections: pd.DataFrame
    residual_frames: np.ndarray
    dropped_frames: np.ndarray


def apply_time_offsets(detections: pd.DataFrame, offsets_s: Sequence[float] | np.ndarray,
                       fps: float | Sequence[float]) -> AppliedOffsets:
    """Move every view's detections to view 0's frames.

    Args:
        detections: canonical ``detections`` table, each view's frames numbered on its own clock.
        offsets_s: (V,) time offsets, seconds (module docstring), one per view ``0 .. V-1``.
        fps: frames per second, one for every view or one per view.

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
    return AppliedOffsets(out.reset_index(drop=True), residual, dropped)
