"""Scoring shared by the calibration sweeps (``scripts/stress_sweep.py``, ``scripts/consumer_sweep.py``): the blocking
checks a calibrated rig fails, its per-view errors against the true cameras (with the alignment fitted on the trusted
views only) and the silent failures, and the distributions' quantiles.

A **silent failure** is a view whose focal error exceeds ``SILENT_FOCAL_PCT`` or whose angle error exceeds
``SILENT_ANGLE_DEG`` in a scene that fails no blocking check (``humancal update`` would exit 0).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import time
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["SILENT_FOCAL_PCT", "SILENT_ANGLE_DEG", "score_calibration", "quantiles"]

SILENT_FOCAL_PCT, SILENT_ANGLE_DEG = 5.0, 3.0
"""A view worse than this in a scene that passes every blocking check (``humancal update`` would exit 0) is a silent
failure."""


def _checks(cameras, people_m, floor_known: bool, body_size_ratio: float, per_view) -> list[str]:
    """The blocking checks of the pipeline's ``extrinsics`` asset that these cameras fail."""
    from humancal.camera import cameras_to_table
    from humancal.tables.plausibility import (
        check_body_size,
        check_cameras_valid,
        check_focal_plausible,
        check_rig_geometry,
        check_views_agree,
    )

    table = cameras_to_table(cameras, "sweep")
    reports = {"cameras_valid": check_cameras_valid(table), "focal_plausible": check_focal_plausible(table),
               "rig_geometry": check_rig_geometry(table, people_m, floor_known=floor_known),
               "people_plausible": check_body_size(body_size_ratio), "views_agree": check_views_agree(per_view)}
    failed = [name for name, report in reports.items() if not report.passed]
    return failed + (["focal_constrained"] if (per_view["focal_status"] != "ok").any() else [])


def _angles_aligned_with_axes(estimated, truth) -> np.ndarray:
    """(V,) angle errors, degrees, after the similarity fitted on the centres *and* a point one rig radius ahead on
    each optical axis. For three views: their triangle of centres alone leaves the alignment's rotation to the
    triangle's shape error (scene 94 of the sweep: 5.2 deg for each of three views whose relative rotations are
    within 0.8 deg of the truth); with two views the centres-only alignment already adds these points."""
    from humancal.calibration.rig_alignment import rig_alignment_points
    from humancal.geometry.alignment import fit_similarity
    from humancal.geometry.rotations import rotation_distance_deg

    def radius(cameras):
        centres = np.stack([c.center_world_m for c in cameras])
        return float(np.linalg.norm(centres - centres.mean(0), axis=1).mean()) or 1.0

    similarity = fit_similarity(rig_alignment_points(estimated, radius(estimated), with_axes=True),
                                rig_alignment_points(truth, radius(truth), with_axes=True))
    aligned = np.stack([similarity.apply_to_camera(c).R_cam_from_world for c in estimated])
    return rotation_distance_deg(aligned, np.stack([c.R_cam_from_world for c in truth]))


def score_calibration(result, true_cameras: list, index: int, far_views: int) -> tuple[dict, list[dict]]:
    """Score a calibration (:class:`~humancal.calibration.ExtrinsicsEstimate`) against the true cameras.

    Args:
        result: what :func:`humancal.calibration.estimate_extrinsics` returned.
        true_cameras: the V true cameras.
        index: the scene's number (written into every view row).
        far_views: how many of the last views stand far back (their rows get ``far = True``).

    Returns:
        The scene's fields (outcome, labels, failed checks, world frame, scale) and one dict per view (errors after the
        alignment of all views and of the trusted ones, the calibration's per-view diagnostics, ``silent_failure``).
    """
    from evaluation.camera_metrics import camera_errors

    fields: dict = {}
    diag = result.diagnostics
    floor_known = diag.floor is not None
    people = diag.floor.floor_points_m if floor_known else diag.people_world_m
    errors = camera_errors(result.cameras, list(true_cameras))
    up_error = float("nan")
    if floor_known:  # the estimated world's up axis, in the true world, against the true up
        up_error = float(np.degrees(np.arccos(np.clip((errors["alignment"].R @ [0.0, 0.0, 1.0])[2], -1.0, 1.0))))
    per_view = diag.per_view
    failed = _checks(result.cameras, people, floor_known, diag.body_size_ratio, per_view)
    fields.update(
        outcome="ok", world_frame=diag.world_frame, floor_problem=diag.floor_problem,
        up_source=diag.floor.up_source if floor_known else "none", up_error_deg=up_error,
        failed_checks=",".join(failed), poorly_constrained=int((per_view["focal_status"] != "ok").sum()),
        scale_error_pct=float(100.0 * (1.0 / errors["alignment"].scale - 1.0)), scale_factor=float(diag.scale_factor),
        body_size_ratio=float(diag.body_size_ratio), mismatched_detections=int(diag.mismatched_detections),
        regroup=diag.regroup, regroup_detections=list(map(int, diag.regroup_detections)),
        extrinsics_timings_s=json.dumps({k: round(v, 2) for k, v in diag.timings_s.items()}),
    )
    # a view's own failure is judged in a frame its flagged neighbours do not set: the similarity that aligns the
    # rigs is fitted again on the views the calibration did not flag (poorly_constrained views can drag a small
    # rig's alignment, and with it every other view's angle, far off)
    trusted = np.flatnonzero(per_view["focal_status"].to_numpy() == "ok")
    own = {k: np.asarray(errors[k], float).copy() for k in ("focal_error_pct", "angle_error_deg")}
    if 2 <= len(trusted) < len(true_cameras):
        again = camera_errors([result.cameras[v] for v in trusted], [true_cameras[v] for v in trusted])
        for k in own:
            own[k][trusted] = again[k]
    if len(trusted) == 3:
        own["angle_error_deg"][trusted] = _angles_aligned_with_axes([result.cameras[v] for v in trusted],
                                                                   [true_cameras[v] for v in trusted])
    views = []
    for v, truth in enumerate(true_cameras):
        bad = (own["focal_error_pct"][v] > SILENT_FOCAL_PCT) or (own["angle_error_deg"][v] > SILENT_ANGLE_DEG)
        views.append({
            "scene": index, "view": v, "focal_gt_px": float(truth.K[0, 0]),
            "k1": float(truth.distortion[0]),
            "pitch_down_deg": float(np.degrees(np.arcsin(np.clip(-truth.R_cam_from_world[2, 2], -1, 1)))),
            "focal_error_pct": float(errors["focal_error_pct"][v]),
            "angle_error_deg": float(errors["angle_error_deg"][v]),
            "focal_error_trusted_pct": float(own["focal_error_pct"][v]),
            "angle_error_trusted_deg": float(own["angle_error_deg"][v]),
            "position_error_mm": float(errors["position_error_mm"][v]),
            "focal_status": per_view["focal_status"].iloc[v], "bundle_status": per_view["bundle_status"].iloc[v],
            "focal_source": per_view["focal_source"].iloc[v],
            "focal_rel_std": float(per_view["focal_rel_std"].iloc[v]),
            "reprojection_rms_px": float(per_view["reprojection_rms_px"].iloc[v]),
            "rotation_edges": int(per_view["rotation_edges"].iloc[v]),
            "agreement": per_view["agreement"].iloc[v], "first_agreement": per_view["first_agreement"].iloc[v],
            "reregistered": bool(per_view["reregistered"].iloc[v]),
            "loo_error_sigma": float(per_view["loo_error_sigma"].iloc[v]),
            "explained_fraction": float(per_view["explained_fraction"].iloc[v]),
            "far": bool(v >= len(true_cameras) - far_views),
            "people_loo_sigma": float(per_view["people_loo_sigma"].iloc[v]),
            "bundle_groups": int((diag.groups["view"] == v).sum()),
            **{name: float(per_view[name].iloc[v]) if name in per_view else float("nan")
               for name in ("k1_std", "cx_std_px", "cy_std_px")},
            "silent_failure": bool(bad and not failed),
        })
    return fields, views


def calibrate_scene(dense, lifted, sizes: list, extrinsics_config, scene_row: dict):
    """The calibration of one sweep scene (intrinsics with ``missing_upright="defer"``, then ``extrinsics_config``),
    timed into ``scene_row["calibrate_s"]``; None, with ``outcome``, ``message`` (and a crash's ``traceback``)
    recorded in ``scene_row``, when it raises: a ``CalibrationError`` is a named failure, anything else a crash."""
    import traceback

    from humancal.calibration import CalibrationError, IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics

    clock = time.perf_counter()
    try:
        intrinsics = estimate_intrinsics(dense, lifted, sizes, IntrinsicsConfig(missing_upright="defer"))
        result = estimate_extrinsics(dense, lifted, intrinsics, extrinsics_config)
    except CalibrationError as error:
        scene_row.update(outcome="calibration_error", message=str(error))
        result = None
    except Exception as error:  # noqa: BLE001 - a crash is what the sweep counts, with its traceback
        scene_row.update(outcome="crash", message=f"{type(error).__name__}: {error}",
                         traceback=traceback.format_exc())
        result = None
    scene_row["calibrate_s"] = time.perf_counter() - clock
    return result


def quantiles(values: pd.Series) -> dict:
    """``n``, median, 90th percentile and maximum of the values that are not NaN (``{"n": 0}`` for none)."""
    values = values.dropna()
    if values.empty:
        return {"n": 0}
    return {"n": int(len(values)), "median": float(values.median()), "p90": float(values.quantile(0.9)),
            "max": float(values.max())}




def run_jobs(jobs: list, run_and_store, init, init_args: tuple, processes: int) -> None:
    """Run the sweep's pending scenes, one job each, printing a progress line per scene as it finishes.

    Args:
        jobs: the jobs (``run_and_store``'s argument).
        run_and_store: runs one job and stores its result; returns the progress line (or ``(index, line)``).
        init: sets a worker up (lifters, body model), called with ``init_args`` in each worker process.
        processes: worker processes (spawned); 1 runs the jobs in this process.
    """
    start = time.perf_counter()

    def report(done: int, out) -> None:
        line = out[1] if isinstance(out, tuple) else out
        print(f"[{done}/{len(jobs)} {time.perf_counter() - start:.0f} s] {line}", flush=True)

    if processes > 1 and jobs:
        with multiprocessing.get_context("spawn").Pool(processes, init, init_args) as pool:
            for done, out in enumerate(pool.imap_unordered(run_and_store, jobs), 1):
                report(done, out)
    elif jobs:
        init(*init_args)
        for done, job in enumerate(jobs, 1):
            report(done, run_and_store(job))


def sweep_arguments(description: str, scenes: int) -> argparse.ArgumentParser:
    """The options every sweep takes: ``--scenes`` (default ``scenes``), ``--seed``, ``--lifters``, ``--out``,
    ``--jobs``, ``--only``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--scenes", type=int, default=scenes)
    parser.add_argument("--seed", type=int, default=0, help="sweep seed")
    parser.add_argument("--lifters", default="shipped",
                        help="comma-separated lifter checkpoints ('shipped' for the packaged weights)")
    parser.add_argument("--out", type=Path, required=True, help="folder for the per-scene results and summaries")
    parser.add_argument("--jobs", type=int, default=1, help="scenes calibrated in parallel (one process each)")
    parser.add_argument("--only", default=None, help="comma-separated scene indices")
    return parser
