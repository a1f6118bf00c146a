"""Camera initialisation from people (the paper's III-B): intrinsics from upright people, extrinsics from
aligned lifted 3D poses, focal lengths recovered across views where single views cannot observe them.

Example:
    >>> from humancal.calibration import estimate_intrinsics, estimate_extrinsics
    >>> intrinsics = estimate_intrinsics(detections, lifted, image_size_px)  # doctest: +SKIP
    >>> result = estimate_extrinsics(detections, lifted, intrinsics)  # doctest: +SKIP
    >>> result.cameras, result.diagnostics.per_view  # doctest: +SKIP

See ``docs/calibration.md`` for the method, the failure modes and measured figures.
"""

from humancal.calibration.extrinsics import estimate_extrinsics
from humancal.calibration.extrinsics_config import ExtrinsicsConfig, ExtrinsicsDiagnostics, ExtrinsicsEstimate
from humancal.calibration.floor import FloorAlignment, align_to_floor
from humancal.calibration.intrinsics import IntrinsicsConfig, IntrinsicsEstimate, estimate_intrinsics
from humancal.calibration.plot import plot_rigs
from humancal.calibration.rig_alignment import Similarity, align_rig
from humancal.calibration.tables import intrinsics_from_table, intrinsics_to_table
from humancal.calibration.types import CalibrationError, LiftedPoses

__all__ = [
    "CalibrationError",
    "LiftedPoses",
    "IntrinsicsConfig",
    "IntrinsicsEstimate",
    "estimate_intrinsics",
    "ExtrinsicsConfig",
    "ExtrinsicsDiagnostics",
    "ExtrinsicsEstimate",
    "estimate_extrinsics",
    "FloorAlignment",
    "align_to_floor",
    "Similarity",
    "align_rig",
    "plot_rigs",
    "intrinsics_to_table",
    "intrinsics_from_table",
]
