"""Views that disagree with the others, found and placed again: the calibration's last step.

After the bundle adjustment every view is scored by the people triangulated without it
(:mod:`.view_agreement`). When some disagree:

1. **isolate**: the view that disagrees most leaves the reference views, the rest are scored again by the views
   left, until those agree with each other (or two are left): one wrong camera that dragged the others no longer
   makes them look wrong;
2. **the views that agree** are adjusted alone (the others held), their people found again with their cameras
   alone (:func:`~humancal.calibration.regroup.regroup_with_cameras`) and adjusted once more;
3. **each view that left** is placed again against those people (:func:`~.reregister.reregister_view`: PnP with
   RANSAC, focal length and who is who unknown);
4. **all views**: groups found again with the new cameras, one bundle adjustment, the agreement scored again.

The repaired rig is kept when fewer views disagree than before (the same number: when its bundle adjustment's
cost per keypoint is lower); the views that still disagree are the caller's to name.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.calibration.bundle import BundleResult, bundle_adjust
from humancal.calibration.regroup import regroup_with_cameras
from humancal.calibration.reregister import reregister_view
from humancal.calibration.view_agreement import AgreementConfig, isolate_disagreeing_views, view_agreement
from humancal.camera import Camera, CameraRig, intrinsic_matrices, intrinsic_matrix
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = ["Adjust", "RepairInputs", "ViewRepair", "agreement_of", "calibration_adjuster", "cameras_of",
           "check_and_repair_views", "people_groups"]

logger = logging.getLogger(__name__)

Adjust = Callable[..., BundleResult]
"""``adjust(fx_px, R_cam_from_world, t_cam_from_world_m, points_world_m, groups, hold_views=())``: one bundle
adjustment of the calibration from the given start."""


@dataclass(frozen=True)
class RepairInputs:
    """What the repair needs of the calibration.

    Attributes:
        detections: every detection.
        lifted: their lifted poses, as given (crop or camera frames).
        principal_points_px: (V, 2).
        image_sizes_px: (V, 2) width, height.
        focal_bounds_px: (V, 2) plausible focal lengths (low, high).
        adjust: the calibration's bundle adjustment (:data:`Adjust`).
        agreement: thresholds of the agreement.
        regroup_max_frames: frames matched when people are found again with cameras for a bundle adjustment.
        people_frames: frames whose every person the agreement's explained fraction uses.
    """

    detections: DenseDetections
    lifted: LiftedPoses
    principal_points_px: np.ndarray
    image_sizes_px: np.ndarray
    focal_bounds_px: np.ndarray
    adjust: Adjust
    agreement: AgreementConfig
    regroup_max_frames: int
    people_frames: int = 40


@dataclass(frozen=True)
class ViewRepair:
    """What :func:`check_and_repair_views` found and did.

    Attributes:
        first: the agreement of the bundle adjustment's rig, one row per view (:func:`view_agreement`).
        final: the agreement of the rig returned.
        isolated: views that left the reference views before the repair (disagreeing once the rest agreed).
        reregistered: views placed again (all of ``isolated`` that a PnP could place).
        kept: whether the repaired rig was kept (False: nothing disagreed, the repair failed, or it was not better).
    """

    first: pd.DataFrame
    final: pd.DataFrame
    isolated: tuple[int, ...] = ()
    reregistered: tuple[int, ...] = ()
    kept: bool = False

    @property
    def disagreeing(self) -> list[int]:
        """Views of the returned rig that still disagree with the others."""
        return self.final.loc[self.final["verdict"] == "disagrees", "view"].astype(int).tolist()

    @property
    def repaired(self) -> list[int]:
        """Views that disagreed before and agree now."""
        if not self.kept:
            return []
        before = set(self.first.loc[self.first["verdict"] == "disagrees", "view"].astype(int))
        return sorted(before & set(self.final.loc[self.final["verdict"] == "ok", "view"].astype(int)))


def cameras_of(ba: BundleResult, inputs: RepairInputs) -> CameraRig:
    """The rig of a bundle adjustment's result."""
    out = []
    for v in range(len(ba.fx_px)):
        K = intrinsic_matrix(ba.fx_px[v], ba.fy_px[v], *inputs.principal_points_px[v])
        w, h = inputs.image_sizes_px[v]
        out.append(Camera(K, ba.R_cam_from_world[v], ba.t_cam_from_world_m[v], int(w), int(h)))
    return CameraRig.from_cameras(out)


def _restrict(groups: list[np.ndarray], view: np.ndarray, keep: Sequence[int]) -> tuple[list[np.ndarray], list[int]]:
    """The groups' detections in ``keep`` only, groups left with fewer than two views dropped; and the index of
    each kept group among ``groups``."""
    out, index = [], []
    for g, rows in enumerate(groups):
        rows = rows[np.isin(view[rows], keep)]
        if len(rows) >= 2:
            out.append(rows)
            index.append(g)
    return out, index


def people_groups(cameras: CameraRig, inputs: RepairInputs) -> list[np.ndarray]:
    """Every person of ``inputs.people_frames`` frames (spread evenly), found by the association with ``cameras``:
    detection rows, one array per person and frame (the explained fraction's people)."""
    return _people_of(list(range(len(cameras))), cameras, inputs, inputs.people_frames)[0]


def agreement_of(cameras: CameraRig, groups: list[np.ndarray], inputs: RepairInputs,
                 reference_views: Sequence[int] | None = None, people: list[np.ndarray] | None = None
                 ) -> pd.DataFrame:
    """:func:`view_agreement` of a rig, its people found with its cameras unless given."""
    people = people_groups(cameras, inputs) if people is None else people
    return view_agreement(cameras, inputs.detections, groups, inputs.agreement, reference_views, people)


def _people_of(views: list[int], cameras: CameraRig, inputs: RepairInputs, max_frames: int | None = None):
    """Groups and keypoints of the people found with the cameras of ``views`` alone (rows of all detections), in at
    most ``max_frames`` frames (default ``inputs.regroup_max_frames``)."""
    d = inputs.detections
    rows = np.flatnonzero(np.isin(d.view, views))
    remap = np.full(len(cameras), -1)
    remap[views] = np.arange(len(views))
    subset = DenseDetections(d.frame[rows], remap[d.view[rows]], d.det_id[rows], d.keypoints_px[rows], d.scores[rows])
    found = regroup_with_cameras(subset, inputs.lifted.subset(rows),
                                 CameraRig.from_cameras([cameras[v] for v in views]),
                                 max_frames or inputs.regroup_max_frames)
    return [rows[g] for g in found.groups], found.points_world_m


def _people_by_frame(groups: list[np.ndarray], points: np.ndarray, frame: np.ndarray) -> dict[int, np.ndarray]:
    by_frame: dict[int, list[np.ndarray]] = {}
    for rows, X in zip(groups, points):
        by_frame.setdefault(int(frame[rows[0]]), []).append(X)
    return {f: np.stack(people) for f, people in by_frame.items()}


def _repair(ba, groups, isolated: list[int], inputs: RepairInputs):
    """Steps 2-4 of the module docstring; returns (bundle result, groups, re-registered views) or None."""
    d, V = inputs.detections, len(ba.fx_px)
    good = [v for v in range(V) if v not in isolated]
    kept, index = _restrict(groups, d.view, good)
    if len(kept) < 3:
        return None
    ba_good = inputs.adjust(ba.fx_px, ba.R_cam_from_world, ba.t_cam_from_world_m, ba.points_world_m[index], kept,
                            hold_views=isolated)
    people_groups, people_points = _people_of(good, cameras_of(ba_good, inputs), inputs)
    if len(people_groups) >= 3:  # the people found again by the agreeing views' cameras, adjusted with them
        ba_good = inputs.adjust(ba_good.fx_px, ba_good.R_cam_from_world, ba_good.t_cam_from_world_m, people_points,
                                people_groups, hold_views=isolated)
    else:
        people_groups = kept
    people = _people_by_frame(people_groups, ba_good.points_world_m, d.frame)
    cameras = list(cameras_of(ba_good, inputs))  # the views placed again replace theirs below
    widths = inputs.image_sizes_px[:, 0].astype(float)
    field = float(np.median(ba_good.fx_px[good] / widths[good]))  # the agreeing views' typical field of view
    placed = []
    for v in isolated:
        found = reregister_view(np.flatnonzero(d.view == v), d, people, inputs.principal_points_px[v],
                                *inputs.image_sizes_px[v], tuple(inputs.focal_bounds_px[v]),
                                focal_guess_px=field * widths[v])
        if found is None:
            logger.info("view %d: no pose of it explains three of its detections by the other views' people", v)
            continue
        logger.info("view %d placed again: focal %.0f px, %.0f %% of %d detections explained", v,
                    found.camera.K[0, 0], 100 * found.explained_fraction, found.scored)
        cameras[v] = found.camera
        placed.append(v)
    if not placed:
        return None
    all_groups, all_points = _people_of(list(range(V)), CameraRig.from_cameras(cameras), inputs)
    if len(all_groups) < 3:
        return None
    f = np.array([c.K[0, 0] for c in cameras])
    R = np.stack([c.R_cam_from_world for c in cameras])
    t = np.stack([c.t_cam_from_world_m for c in cameras])
    return inputs.adjust(f, R, t, all_points, all_groups), all_groups, placed


def calibration_adjuster(detections, lifted_as_given, pp, bounds, f0, prior_rel, config) -> Adjust:
    """The calibration's bundle adjustment as ``adjust(f, R, t, points, groups, hold_views=())``: square pixels, the
    focal priors and bounds of the calibration, the lifted poses turned into camera frames at ``f``."""
    def adjust(f, R, t, points, groups, hold_views=()):
        lifted = (lifted_as_given.in_camera_frame(intrinsic_matrices(f, f, pp[:, 0], pp[:, 1])[detections.view]) if lifted_as_given.frame == "crop"
                  else lifted_as_given)
        return bundle_adjust(
            detections, lifted, groups, points, f, f, pp, R, t, square_pixels=config.square_pixels,
            focal_prior_px=f0, focal_prior_rel_std=prior_rel, shape_std_m=config.shape_std_m,
            group_scale_std=config.person_scale_std, focal_bounds_px=bounds, max_iterations=config.bundle_iterations,
            hold_views=hold_views)

    return adjust


def check_and_repair_views(ba: BundleResult, groups: list[np.ndarray], inputs: RepairInputs, repair: bool = True
                           ) -> tuple[BundleResult, list[np.ndarray], ViewRepair]:
    """Score every view against the others and repair the rig where some disagree (see the module docstring).

    Args:
        ba, groups: the calibration's bundle adjustment and its groups.
        inputs: what the repair needs.
        repair: False: the views are scored, none is placed again.

    Returns:
        (bundle result, groups, :class:`ViewRepair`): the repaired ones when the repair was kept, else those given.
    """
    cameras = cameras_of(ba, inputs)
    people = people_groups(cameras, inputs)
    first = agreement_of(cameras, groups, inputs, people=people)
    if not repair or not (first["verdict"] == "disagrees").any():
        return ba, groups, ViewRepair(first, first)
    isolated, _ = isolate_disagreeing_views(cameras, inputs.detections, groups, inputs.agreement, people, first)
    logger.info("views %s disagree with the others (%s): placing them again against the people of views %s",
                isolated, "; ".join(f"view {r.view}: {r.reason}" for r in first.itertuples()
                                    if r.verdict == "disagrees"),
                [v for v in range(len(ba.fx_px)) if v not in isolated])
    repaired = _repair(ba, groups, isolated, inputs) if isolated else None
    if repaired is None:
        return ba, groups, ViewRepair(first, first, tuple(isolated))
    ba_new, groups_new, placed = repaired
    final = agreement_of(cameras_of(ba_new, inputs), groups_new, inputs)
    before, after = (first["verdict"] == "disagrees").sum(), (final["verdict"] == "disagrees").sum()
    better = after < before or (after == before and _cost_per_keypoint(ba_new, groups_new)
                                < _cost_per_keypoint(ba, groups))
    if not better:
        logger.info("the repaired rig is not better (%d views disagree, were %d): the first one is kept", after, before)
        return ba, groups, ViewRepair(first, first, tuple(isolated), tuple(placed))
    return ba_new, groups_new, ViewRepair(first, final, tuple(isolated), tuple(placed), kept=True)


def _cost_per_keypoint(ba: BundleResult, groups: list[np.ndarray]) -> float:
    return float(ba.cost) / max(sum(len(g) for g in groups), 1)
