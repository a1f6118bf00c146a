"""Cameras the user already knows (a capture's ``cameras`` option): used instead of a calibration, or as anchors.

* **Every view known**: the calibration is not run. The known cameras are checked against the people instead: the
  detections are matched across views with them (:func:`~humancal.calibration.regroup.regroup_with_cameras`), and
  every view is scored by the people triangulated without it (:mod:`.view_agreement`): a camera file in another
  view order, another unit or of another session disagrees.
* **Some views known**: the calibration runs with their focal lengths and principal points as given; its rig is
  then moved onto the known cameras (the rigid transform of the one known camera, or the similarity of two or more
  known centres, which then also sets the scale) and adjusted once more with the known cameras held: they keep
  their intrinsics and poses, and the world is theirs.

The known cameras come as pinholes: their lens distortion is taken out of the detections before the method sees
them (:func:`humancal.captures.cameras.undistort_known_views`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from humancal.calibration.bundle import BundleResult
from humancal.calibration.extrinsics_config import ExtrinsicsConfig, ExtrinsicsDiagnostics, ExtrinsicsEstimate
from humancal.calibration.intrinsics import IntrinsicsEstimate
from humancal.calibration.regroup import regroup_with_cameras
from humancal.calibration.rig_alignment import align_rig
from humancal.calibration.types import hip_midpoints
from humancal.calibration.view_agreement import view_agreement
from humancal.calibration.world_scale import body_size_ratio
from humancal.camera import Camera, CameraRig
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = ["KNOWN_FOCAL_REL_STD", "anchor_to_known", "known_rig_estimate", "with_known_intrinsics"]

KNOWN_FOCAL_REL_STD = 1e-3
"""Prior std of a known focal length in the calibration before it is held (relative)."""


def with_known_intrinsics(intrinsics: Sequence[IntrinsicsEstimate], known: Mapping[int, Camera]
                          ) -> list[IntrinsicsEstimate]:
    """The single-view estimates with the known views' intrinsics (``K``) in their place (status ``"ok"``)."""
    return [dataclasses.replace(e, K=known[e.view].K.copy(), status="ok", focal_rel_uncertainty=KNOWN_FOCAL_REL_STD)
            if e.view in known else e for e in intrinsics]


def _centres(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return -np.einsum("vji,vj->vi", R, t)


def anchor_to_known(ba: BundleResult, known: Mapping[int, Camera], adjust, groups: list[np.ndarray]) -> BundleResult:
    """The calibrated rig moved onto the known cameras and adjusted again with them held.

    Args:
        ba: the calibration's bundle adjustment.
        known: the known cameras by view.
        adjust: ``adjust(f, R, t, points, groups, hold_views=...)``: the calibration's bundle adjustment.
        groups: its groups.
    """
    views = sorted(known)
    R_k = np.stack([known[v].R_cam_from_world for v in views])
    t_k = np.stack([known[v].t_cam_from_world_m for v in views])
    if len(views) == 1:  # the rigid motion that puts the calibrated camera where the known one stands
        v = views[0]
        rotation = R_k[0].T @ ba.R_cam_from_world[v]  # world_known <- world_calibrated
        scale = 1.0
        shift = known[v].center_world_m - rotation @ _centres(ba.R_cam_from_world, ba.t_cam_from_world_m)[v]
    else:  # the similarity of the known views' centres (and, for two, points ahead on their optical axes)
        calibrated = [Camera(known[v].K, ba.R_cam_from_world[v], ba.t_cam_from_world_m[v], known[v].width_px,
                             known[v].height_px) for v in views]
        similarity = align_rig(calibrated, [known[v] for v in views])
        rotation, scale, shift = similarity.R, similarity.scale, similarity.t
    R = ba.R_cam_from_world @ rotation.T
    centres = scale * _centres(ba.R_cam_from_world, ba.t_cam_from_world_m) @ rotation.T + shift
    t = -np.einsum("vij,vj->vi", R, centres)
    R[views], t[views] = R_k, t_k
    f = ba.fx_px.copy()
    f[views] = [known[v].K[0, 0] for v in views]
    points = scale * ba.points_world_m @ rotation.T + shift
    return adjust(f, R, t, points, groups, hold_views=views)


def known_rig_estimate(detections: DenseDetections, lifted: LiftedPoses, cameras: CameraRig,
                       config: ExtrinsicsConfig) -> ExtrinsicsEstimate:
    """Every view known: the cameras as given, with the diagnostics of their agreement with the people.

    Args:
        detections: the detections (undistorted where the known lenses distort).
        lifted: their lifted poses (crop or camera frames).
        cameras: the known rig, one camera per view (pinholes).
        config: the calibration's settings (the agreement's thresholds, the frames matched).
    """
    found = regroup_with_cameras(detections, lifted, cameras, config.regroup_max_frames or 150)
    agreement = view_agreement(cameras, detections, found.groups, config.agreement(), people=found.groups)
    V = len(cameras)
    per_view = pd.DataFrame({
        "view": np.arange(V), "focal_px": [c.K[0, 0] for c in cameras], "focal_rel_std": 0.0,
        "focal_status": "ok", "focal_source": "known", "bundle_status": "held",
        "agreement": agreement["verdict"].to_numpy(), "agreement_reason": agreement["reason"].to_numpy(),
        "loo_error_sigma": agreement["loo_median_sigma"].to_numpy(),
        "people_loo_sigma": agreement["people_loo_sigma"].to_numpy(),
        "explained_fraction": agreement["explained_fraction"].to_numpy(),
        "first_agreement": agreement["verdict"].to_numpy(), "reregistered": False,
    })
    rows = np.concatenate(found.groups) if found.groups else np.zeros(0, np.int64)
    group_table = pd.DataFrame({"frame": detections.frame[rows], "view": detections.view[rows],
                                "det_id": detections.det_id[rows],
                                "group": np.repeat(np.arange(len(found.groups)), [len(g) for g in found.groups])})
    diagnostics = ExtrinsicsDiagnostics(
        per_view, pd.DataFrame(columns=["view_a", "view_b", "support", "residual_deg"]), group_table, None,
        float("nan"), world_frame="known_cameras", people_world_m=hip_midpoints(found.points_world_m),
        body_size_ratio=body_size_ratio(found.points_world_m, lifted, found.groups))
    return ExtrinsicsEstimate(CameraRig.of(cameras), diagnostics)
