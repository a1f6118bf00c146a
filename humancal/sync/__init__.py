"""Unsynchronised videos: each view's time offset estimated from the people's motion, and the detections moved to
one clock (``docs/capture.md``, "Unsynchronised videos").

Example:
    >>> from humancal.sync import SyncConfig, apply_time_offsets, estimate_time_offsets
    >>> offsets = estimate_time_offsets(detections, fps=30.0, lifter=lifter)  # doctest: +SKIP
    >>> offsets.status, offsets.offset_frames  # doctest: +SKIP
    (('ok', 'ok', 'ok'), array([ 0., 12., -7.]))
    >>> synced = apply_time_offsets(detections, offsets.offset_s, 30.0, interpolate=True)  # doctest: +SKIP
"""

from humancal.sync.apply import AppliedOffsets, apply_time_offsets
from humancal.sync.interpolate import ViewAtTimes, view_at_times
from humancal.sync.offsets import (
    STATUSES,
    PairOffset,
    SyncConfig,
    TimeOffsets,
    estimate_time_offsets,
    per_view_fps,
    tentative_offsets_s,
)
from humancal.sync.periods import PeriodConfig, PeriodSearch, misplaced_period_s, regroup_by_period
from humancal.sync.with_cameras import CameraCheck, CameraCheckConfig, check_offsets_with_cameras
from humancal.sync.signals import SIGNAL_KINDS, TrackSignals, track_signals
from humancal.sync.tracks import link_view_tracks

__all__ = [
    "STATUSES",
    "SIGNAL_KINDS",
    "AppliedOffsets",
    "CameraCheck",
    "CameraCheckConfig",
    "TrackSignals",
    "PairOffset",
    "PeriodConfig",
    "PeriodSearch",
    "SyncConfig",
    "TimeOffsets",
    "ViewAtTimes",
    "apply_time_offsets",
    "check_offsets_with_cameras",
    "estimate_time_offsets",
    "link_view_tracks",
    "misplaced_period_s",
    "regroup_by_period",
    "track_signals",
    "per_view_fps",
    "tentative_offsets_s",
    "view_at_times",
]
