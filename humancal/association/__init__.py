"""Who is who: affinities between detections, cross-view matching and tracking (``docs/association.md``)."""

from humancal.association.affinity import (
    AffinityConfig,
    PairAffinities,
    combine_affinity,
    cross_view_pairs,
    detection_track_affinity,
    pair_affinities,
)
from humancal.association.cycle_matching import (
    FrameMatching,
    WarmStart,
    carry_over,
    clusters_to_matrix,
    match_frame,
    match_frames,
    relaxation_objective,
    round_to_clusters,
    solve_relaxation_cvxpy,
)
from humancal.association.detection_geometry import DetectionGeometry, detection_geometry
from humancal.association.matching_config import MatchingConfig
from humancal.association.track_smoothing import SmoothingConfig, smooth_tracks
from humancal.association.tracking_config import TrackingConfig
from humancal.association.tracking import (
    SKELETONS3D_SCHEMA,
    AssociationResult,
    associate,
    to_associations_table,
    to_skeletons_table,
)

__all__ = [
    "AffinityConfig",
    "DetectionGeometry",
    "PairAffinities",
    "SmoothingConfig",
    "combine_affinity",
    "cross_view_pairs",
    "detection_geometry",
    "detection_track_affinity",
    "pair_affinities",
    "smooth_tracks",
    "FrameMatching",
    "MatchingConfig",
    "WarmStart",
    "carry_over",
    "clusters_to_matrix",
    "match_frame",
    "match_frames",
    "relaxation_objective",
    "round_to_clusters",
    "solve_relaxation_cvxpy",
    "SKELETONS3D_SCHEMA",
    "AssociationResult",
    "TrackingConfig",
    "associate",
    "to_associations_table",
    "to_skeletons_table",
]
