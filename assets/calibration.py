"""Per sequence: lifted detections, then the camera initialisation from people (intrinsics, extrinsics)."""

import tempfile
import time
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd
import threadpoolctl

from assets.checks import check_result
from assets.common import png_metadata, sequence_asset, table_output
from assets.settings import ExtrinsicsSettings, IntrinsicsSettings
from humancal.calibration import (
    estimate_extrinsics,
    estimate_intrinsics,
    intrinsics_from_table,
    intrinsics_to_table,
    plot_rigs,
)
from humancal.camera import cameras_by_view, cameras_to_table, pinhole
from humancal.captures.cameras import undistort_known_views
from humancal.datasets.inputs import sequence_principal_points
from humancal.keypoints import NUM_JOINTS
from humancal.lifter import lift_detections_table, lifted_from_table, load_lifter
from humancal.tables.plausibility import (
    CheckReport,
    check_body_size,
    check_cameras_valid,
    check_focal_plausible,
    check_rig_geometry,
    check_views_agree,
)
from resources.datasets import DatasetsResource
from resources.torch import TorchResource

MIN_UPRIGHT_PER_VIEW = 20
"""Below this many upright standing detections in a view, the intrinsics check warns."""


def _calibration_inputs(detections: pd.DataFrame):
    return lifted_from_table(detections)


def _view_names(views: pd.DataFrame, num_views: int) -> list[str] | None:
    """The views' names in view order, for the calibration's messages (None when the table does not name them)."""
    if not {"view", "name"} <= set(views.columns) or len(views) != num_views:
        return None
    return views.sort_values("view")["name"].astype(str).tolist()


def _image_sizes(views: pd.DataFrame) -> list[tuple[int, int]]:
    rows = views.sort_values("view")
    return list(zip(rows["width_px"].astype(int), rows["height_px"].astype(int)))


def _single_threaded_blas():
    """The calibration solves many small systems: multi-threaded BLAS only adds overhead there (measured 2-3x
    slower on a busy 2-core machine)."""
    return threadpoolctl.threadpool_limits(1)


@sequence_asset("lifted_detections", code_version="2")
def detections(
    context: dg.AssetExecutionContext, torch_runtime: TorchResource, raw_detections: pd.DataFrame,
    lifter_checkpoint: dict, known_cameras: pd.DataFrame,
) -> dg.Output:
    """Every 2D detection with its lifted root-relative 3D pose (crop frame), height and upright score; the
    detections of views whose known camera distorts are undistorted first (the method works with pinholes)."""
    start = time.perf_counter()
    if len(known_cameras):
        raw_detections = undistort_known_views(raw_detections, known_cameras)
    with torch_runtime.applied() as device:
        table = lift_detections_table(load_lifter(lifter_checkpoint, device), raw_detections, context.partition_key)
    first = table.iloc[::NUM_JOINTS]  # one row per detection
    lifted = first["lifted"].to_numpy(bool)
    upright = first["upright_score"].to_numpy()[lifted]
    context.log.info(f"lifted {lifted.sum()} of {len(first)} detections in {time.perf_counter() - start:.1f} s")
    return table_output(
        table, "lifted_detections", rows=len(table), detections=len(first), lifted=int(lifted.sum()),
        upright_fraction=float(np.mean(upright >= 0.5)) if len(upright) else 0.0,
        median_height_m=float(np.median(first["height_m"].to_numpy()[lifted])) if lifted.any() else float("nan"),
        seconds=round(time.perf_counter() - start, 2),
    )


@sequence_asset(
    "intrinsics",
    code_version="2",
    check_specs=[
        dg.AssetCheckSpec("focal_plausible", asset="intrinsics",
                          description="each well-conditioned single-view focal gives a 10-140 deg horizontal field "
                                      "of view (ill-conditioned views are recovered by the extrinsics step)"),
        dg.AssetCheckSpec("enough_upright_people", asset="intrinsics",
                          description=f"at least {MIN_UPRIGHT_PER_VIEW} upright standing detections per view (warns)"),
    ],
)
def intrinsics(
    context: dg.AssetExecutionContext, config: IntrinsicsSettings, datasets: DatasetsResource,
    detections: pd.DataFrame, views: pd.DataFrame
):
    """Per view: focal length from the upright people's vertical vanishing point and heights (the paper's III-B),
    with the diagnostics (inliers, vanishing point, camera height and tilt, conditioning). The principal point is the
    image centre unless the sequence's datasets entry gives it (option ``principal_point``)."""
    start = time.perf_counter()
    dense, lifted = _calibration_inputs(detections)
    sizes = _image_sizes(views)
    try:
        known_pp = sequence_principal_points(datasets.spec(context.partition_key), sizes)
    except ValueError as error:
        raise dg.Failure(str(error)) from error
    if known_pp is not None:
        context.log.info(f"principal points given by the datasets entry: {known_pp}")
    with _single_threaded_blas():
        estimates = estimate_intrinsics(dense, lifted, sizes, config.to_library(), principal_point_px=known_pp)
    table = intrinsics_to_table(context.partition_key, estimates)
    seconds = time.perf_counter() - start
    context.log.info(f"intrinsics of {len(estimates)} views in {seconds:.1f} s")
    yield table_output(
        table, "intrinsics", rows=len(table), seconds=round(seconds, 2),
        ill_conditioned_views=int((table["status"] != "ok").sum()),
        per_view=dg.MetadataValue.md(table.drop(columns="sequence").to_markdown(index=False, floatfmt=".3g")),
    )
    yield check_result(context, "focal_plausible", _single_view_focal_report(table))
    yield check_result(context, "enough_upright_people", _upright_report(table), severity=dg.AssetCheckSeverity.WARN)


def _single_view_focal_report(table: pd.DataFrame) -> CheckReport:
    """Focal plausibility of the well-conditioned single-view estimates; "not checked" when there are none."""
    flagged = table[table["status"] != "ok"]
    if len(flagged) == len(table):
        why = ("no view" if table.empty else
               f"every view's single-view focal is flagged ({', '.join(sorted(set(flagged['status'])))}): "
               "the extrinsics step recovers them, and its own focal_plausible check covers them")
        return CheckReport.nothing_to_check(why, {"views": float(len(table)), "flagged_views": float(len(flagged))})
    report = check_focal_plausible(table[table["status"] == "ok"])
    if len(flagged):
        note = f"; views {flagged['view'].tolist()} flagged {sorted(set(flagged['status']))} (not checked)"
        report = CheckReport(report.passed, report.description + note, report.figures, report.checked)
    return report


def _upright_report(table: pd.DataFrame) -> CheckReport:
    if table.empty:
        return CheckReport.nothing_to_check("no view")
    few = table[table["num_candidates"] < MIN_UPRIGHT_PER_VIEW]
    return CheckReport(
        few.empty,
        "every view has enough upright standing detections" if few.empty else
        "; ".join(f"view {r.view}: {r.num_candidates} upright detections" for r in few.itertuples()),
        {"min_upright_detections": float(table["num_candidates"].min())},
        checked=len(table),
    )


@sequence_asset(
    "cameras",
    code_version="12",
    check_specs=[
        dg.AssetCheckSpec("cameras_valid", asset="extrinsics", blocking=True,
                          description="finite positive focal, principal point inside, right-handed rotations"),
        dg.AssetCheckSpec("focal_plausible", asset="extrinsics", blocking=True,
                          description="each focal gives a 10-140 deg horizontal field of view"),
        dg.AssetCheckSpec("rig_geometry", asset="extrinsics", blocking=True,
                          description="cameras above the floor, each with most people in front and in its image"),
        dg.AssetCheckSpec("views_agree", asset="extrinsics", blocking=True,
                          description="every view agrees with the people the other views triangulate (after any "
                                      "repair) and its focal is not at a bound of the plausible range"),
        dg.AssetCheckSpec("focal_constrained", asset="extrinsics", blocking=True,
                          description="every focal determined to 5 % (relative std of the bundle adjustment): a looser "
                                      "one is as likely as not more than 5 % off"),
        dg.AssetCheckSpec("people_plausible", asset="extrinsics", blocking=True,
                          description="the people triangulated with these cameras have their lifted size (0.8-1.25)"),
        dg.AssetCheckSpec("floor_found", asset="extrinsics",
                          description="the people gave an up direction and a floor (else the cameras are in camera "
                                      "0's frame; warns)"),
    ],
)
def extrinsics(
    context: dg.AssetExecutionContext,
    config: ExtrinsicsSettings,
    detections: pd.DataFrame,
    intrinsics: pd.DataFrame,
    views: pd.DataFrame,
    known_cameras: pd.DataFrame,
):
    """The calibrated cameras: rotations from aligned lifted poses, translations, focal lengths and each lens's
    radial distortion refined (focal lengths recovered where single views could not observe them) by a multi-view
    bundle adjustment, every view checked
    against the people the others triangulate (and placed again where it disagrees); world Z up, floor at z = 0,
    metric scale from the people's limbs. A capture's known cameras are used as given (all views known) or as
    anchors (some views: the world is theirs); they enter as pinholes (their detections were undistorted)."""
    start = time.perf_counter()
    dense, lifted = _calibration_inputs(detections)
    known = {v: pinhole(c) for v, c in cameras_by_view(known_cameras).items()} if len(known_cameras) else {}
    if known:
        context.log.info(f"known cameras of views {sorted(known)}: "
                         + ("used as given" if len(known) == len(views) else "the others calibrated around them"))
    with _single_threaded_blas():
        estimates = intrinsics_from_table(intrinsics)
        result = estimate_extrinsics(dense, lifted, estimates, config.to_library(),
                                     view_names=_view_names(views, len(estimates)), known=known)
    table = cameras_to_table(result.cameras, context.partition_key)
    seconds = time.perf_counter() - start
    floor = result.diagnostics.floor
    # the rig picture and the rig check need people on the floor; without a floor, their own positions
    people = floor.floor_points_m if floor is not None else result.diagnostics.people_world_m
    with tempfile.TemporaryDirectory() as tmp:
        png = plot_rigs(result.cameras, None, people, Path(tmp) / "rig.png",
                        title=f"{context.partition_key}: estimated cameras and people on the floor")
        picture = png_metadata(png, "estimated rig")
    per_view = result.diagnostics.per_view
    context.log.info(f"extrinsics of {len(table)} views in {seconds:.1f} s")
    yield table_output(
        table, "cameras", rows=len(table), seconds=round(seconds, 2), rig=picture,
        per_view=dg.MetadataValue.md(per_view.to_markdown(index=False, floatfmt=".3g")),
        bundle_inlier_fraction=float(result.diagnostics.bundle_inlier_fraction),
        world_frame=result.diagnostics.world_frame,
        up_source=floor.up_source if floor is not None else "none",
        up_std_deg=float(floor.up_std_deg) if floor is not None else float("nan"),
        body_size_ratio=float(result.diagnostics.body_size_ratio),
        mismatched_detections=int(result.diagnostics.mismatched_detections),
        regroup=result.diagnostics.regroup,
        regroup_detections=" -> ".join(map(str, result.diagnostics.regroup_detections)),
        scale_factor=float(result.diagnostics.scale_factor),
        views_repaired=", ".join(map(str, np.flatnonzero(per_view["reregistered"].to_numpy()))) or "none",
        lens=result.diagnostics.lens.reason if result.diagnostics.lens is not None else "known cameras",
    )
    rig = check_rig_geometry(table, people, floor_known=floor is not None)
    views_agree = check_views_agree(per_view, _view_names(views, len(table)))
    for name, report in (("cameras_valid", check_cameras_valid(table)), ("focal_plausible", check_focal_plausible(table)),
                         ("rig_geometry", rig), ("views_agree", views_agree),
                         ("people_plausible", check_body_size(result.diagnostics.body_size_ratio))):
        yield check_result(context, name, report)
    yield check_result(context, "focal_constrained", _focal_constrained_report(per_view, views))
    yield check_result(context, "floor_found", _floor_report(result.diagnostics, config.align_floor),
                       severity=dg.AssetCheckSeverity.WARN)


def _floor_report(diagnostics, asked: bool) -> CheckReport:
    if diagnostics.world_frame == "known_cameras":
        return CheckReport(True, "the known cameras set the world frame (no floor alignment)", {}, checked=1)
    if not asked:
        return CheckReport.nothing_to_check("the floor alignment is switched off (align_floor: false)")
    floor = diagnostics.floor
    if floor is None:
        return CheckReport(False, f"no floor: {diagnostics.floor_problem}; the cameras are in camera 0's frame "
                                  "(camera 0 at the origin, OpenCV axes)", {}, checked=1)
    return CheckReport(True, f"up from {floor.up_source} (+- {floor.up_std_deg:.2f} deg), floor from "
                             f"{floor.contact_groups} people ({floor.standing_groups} standing), contact rms "
                             f"{100 * floor.floor_rms_m:.1f} cm",
                       {"up_std_deg": float(floor.up_std_deg), "floor_rms_m": float(floor.floor_rms_m),
                        "standing_groups": float(floor.standing_groups)}, checked=1)


def _focal_constrained_report(per_view: pd.DataFrame, views: pd.DataFrame) -> CheckReport:
    """Every focal determined to 5 %; a failure names the loose views and the ways out."""
    if per_view.empty:
        return CheckReport.nothing_to_check("no view")
    names = _view_names(views, len(per_view))
    label = lambda v: f"view {v} ({names[v]})" if names else f"view {v}"  # noqa: E731
    loose = per_view[per_view["focal_status"] != "ok"]
    problems = [f"{label(r.view)}: focal {r.focal_px:.0f} px "
                + (f"+- {100 * r.focal_rel_std:.0f} %" if np.isfinite(r.focal_rel_std)
                   else f"undetermined ({r.bundle_status.replace('_', ' ')})") for r in loose.itertuples()]
    return CheckReport(
        loose.empty,
        "every focal is determined to 5 %" if loose.empty else "; ".join(problems)
        + ": the people do not determine these focal lengths to 5 % (too few frames, people who hardly move, or a "
          "camera far from the others). Film people moving through the shared field of view for longer, give the "
          "known cameras of these views (--cameras with --known-views), or leave them out (--drop-view)",
        {"max_focal_rel_std": float(per_view["focal_rel_std"].replace(np.inf, np.nan).max())},
        checked=len(per_view),
    )
