"""Who is who: affinities between detections, cross-view matching and tracking (``docs/association.md``)."""

from humancal.association.affinity import (
    AffinityConfig,
    DetectionGeometry,
    PairAffinities,
    combine_affinity,
    cross_view_pairs,
    detection_geometry,
    detection_track_affinity,
    pair_affinities,
    rigid_residual_rms_m,
)

__all__ = [
    "AffinityConfig",
    "DetectionGeometry",
    "PairAffinities",
    "combine_affinity",
    "cross_view_pairs",
    "detection_geometry",
    "detection_track_affinity",
    "pair_affinities",
    "rigid_residual_rms_m",
]
