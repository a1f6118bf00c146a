"""The settings of the association and tracking (:func:`humancal.association.associate`), apart from the code that
reads them, so that its stages (:mod:`~humancal.association.tracks`, ...) can name the type without importing the
conductor."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from humancal.association.affinity import AffinityConfig
from humancal.association.matching_config import MatchingConfig
from humancal.association.track_smoothing import SmoothingConfig
from humancal.config import Config, at_least, in_range, positive

__all__ = ["TrackingConfig"]


@dataclass(frozen=True)
class TrackingConfig(Config):
    """Settings of :func:`associate` (defaults chosen on synthetic scenes, ``docs/association.md``).

    Attributes:
        affinity: the affinity's weights and scales.
        matching: the matching's solver settings (its ``match_threshold`` is replaced by ``match_threshold``).
        match_threshold: affinity a pair must exceed to gain from being matched, in [0, 1].
        temporal: whether the temporal term (detections against the previous frame's tracks) is used.
        fps: frame rate of the sequence, frames per second (turns the durations below into frames).
        reid_window_s: how long a lost track waits to be re-identified, seconds (>= 0); later it is closed and a
            returning person starts a new track.
        assign_distance_m: largest median 3D joint distance between a cluster's skeleton and a track's
            predicted skeleton one frame later for the cluster to continue the track, metres.
        reid_speed_mps: after a gap the distance allowed grows by this speed times the gap, metres per second.
        bone_tolerance: after a gap, the median relative difference of the body's bone lengths (arms, legs,
            shoulder and hip widths, torso sides) between a cluster and a track must stay below it (> 0).
        min_views: views a cluster needs to start a track (>= 2).
        min_track_s: a track observed for less than this is rejected as a false positive, seconds (>= 0).
        stitch_window_s: when ``num_people`` is not given, a track that starts at most this long after another
            one ended continues it when the two share bone lengths and one could walk to the other (0: never).
        outlier_threshold_px: triangulation drops, per joint, the views that reproject farther than this, pixels.
        merge_distance_m: two clusters of one frame from different views are one person split in two, and are
            merged, when their skeletons' median joint distance is below this and the larger one reprojects onto
            every detection of the smaller one within ``outlier_threshold_px`` (median over the joints), metres
            (0: never merged).
        complete_clusters: whether a detection no cluster took joins the one cluster of its frame that lacks its
            view and reprojects onto it within ``outlier_threshold_px`` (left and right swapped or not).
        num_people: the number of people if known (at most this many ids are kept), or None to estimate it.
        smoothing: the temporal refinement of the tracked skeletons (``smoothing.enabled`` False: the
            frame-by-frame triangulation as it is).
    """

    affinity: AffinityConfig = field(default_factory=AffinityConfig)
    matching: MatchingConfig = field(default_factory=MatchingConfig)
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)
    match_threshold: float = field(default=0.3, metadata=in_range(0, 1))
    temporal: bool = True
    fps: float = field(default=30.0, metadata=positive())
    reid_window_s: float = field(default=3.0, metadata=at_least(0))
    assign_distance_m: float = field(default=0.75, metadata=positive())
    reid_speed_mps: float = field(default=1.5, metadata=at_least(0))
    bone_tolerance: float = field(default=0.2, metadata=positive())
    min_views: int = field(default=2, metadata=at_least(2, integer=True))
    min_track_s: float = field(default=0.3, metadata=at_least(0))
    stitch_window_s: float = field(default=20.0, metadata=at_least(0))
    outlier_threshold_px: float = field(default=25.0, metadata=positive())
    merge_distance_m: float = field(default=0.4, metadata=at_least(0))
    complete_clusters: bool = True
    num_people: int | None = field(default=None, metadata=at_least(1, integer=True, optional=True))

    def __post_init__(self) -> None:
        for name, kind in (("affinity", AffinityConfig), ("matching", MatchingConfig), ("smoothing", SmoothingConfig)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"TrackingConfig.{name} must be a {kind.__name__}, got {type(getattr(self, name)).__name__}")
        super().__post_init__()

    @property
    def matching_config(self) -> MatchingConfig:
        """The matching settings with this config's ``match_threshold``."""
        return replace(self.matching, match_threshold=self.match_threshold)
