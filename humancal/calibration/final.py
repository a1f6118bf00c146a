"""Which cameras a run ends with: the refined ones when they agree with the people, else the calibration's.

The body fit refines the cameras together with the people. It is the better rig on most captures, not on all
(real captures: better on 4 of 7, worse on 3), and a refinement can drag one view away. The final cameras are the
refined ones when every view of them agrees with the people the other views triangulate
(:func:`~humancal.calibration.view_agreement.agreement_with_people`, the association's people) as well as the
calibration's cameras do; else the calibration's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.calibration.lens import undistorted_detections
from humancal.calibration.view_agreement import (
    AgreementConfig,
    agreement_with_people,
    isolate_disagreeing_views,
    person_clusters,
)
from humancal.camera import CameraRig, pinhole
from humancal.tables.detections import DenseDetections

__all__ = ["FinalCameras", "choose_final_cameras", "FINAL_SOURCES"]

FINAL_SOURCES = ("refined_cameras", "extrinsics")
"""Where the final cameras come from: the body fit's refined cameras, or the calibration's."""


@dataclass(frozen=True)
class FinalCameras:
    """The cameras a run ends with.

    Attributes:
        rig: the cameras.
        source: one of :data:`FINAL_SOURCES`.
        reason: why, in words.
        agreement: the agreement of the chosen rig with the people (:func:`agreement_with_people`).
    """

    rig: CameraRig
    source: str
    reason: str
    agreement: pd.DataFrame

    @property
    def per_view(self) -> pd.DataFrame:
        """The agreement in the columns :func:`humancal.tables.plausibility.check_views_agree` reads (the focal lengths'
        uncertainty is the calibration's business: not judged again here)."""
        a = self.agreement
        return pd.DataFrame({"view": a["view"], "focal_px": self.rig.K[:, 0, 0], "focal_rel_std": 0.0,
                             "bundle_status": "ok", "agreement": a["verdict"], "agreement_reason": a["reason"],
                             "loo_error_sigma": a["loo_median_sigma"]})


def choose_final_cameras(initial: CameraRig, refined: CameraRig | None, detections: DenseDetections,
                         person_id: np.ndarray, config: AgreementConfig | None = None) -> FinalCameras:
    """The final cameras of a run (see the module docstring).

    Args:
        initial: the calibration's cameras.
        refined: the body fit's cameras (None: no refinement).
        detections: the detections.
        person_id: (D,) the association's person of each detection (-1: none).
        config: thresholds of the agreement.
    """
    first = agreement_with_people(*_pinhole_image(initial, detections), person_id, config)
    if refined is None:
        return FinalCameras(initial, "extrinsics", "no refinement ran", first)
    cameras, seen = _pinhole_image(refined, detections)
    again = agreement_with_people(cameras, seen, person_id, config)
    if ((again["verdict"] == "disagrees") & (first["verdict"] != "disagrees")).any():
        clusters = person_clusters(seen, person_id)
        culprits, _ = isolate_disagreeing_views(cameras, seen, clusters, config or AgreementConfig(), clusters,
                                                again)
        return FinalCameras(initial, "extrinsics", f"the refinement moved views {sorted(culprits)} out of agreement "
                                                   "with the people the other views place", first)
    return FinalCameras(refined, "refined_cameras", "every view of the refined cameras agrees with the people the "
                                                    "other views place", again)


def _pinhole_image(rig: CameraRig, detections: DenseDetections) -> tuple[CameraRig, DenseDetections]:
    """The rig's cameras as pinholes and the detections moved to their pinhole images (the agreement's geometry
    is a pinhole's); the rig and detections as given when no lens distorts."""
    if not np.any(rig.distortion):
        return rig, detections
    return CameraRig.from_cameras([pinhole(c) for c in rig]), undistorted_detections(detections, rig.K, rig.distortion)
