"""Sweep the camera initialisation over seeded synthetic scenes (and Shelf when its data is present).

Each synthetic scene draws 2-8 people, 3-8 views (ring, or an arc for one scene in four), a focal range inside
500-2500 px and 60-150 frames, with the generator's default detector noise. The lifted poses come from either

* ``--lifted stand-in`` (default without ``--lifter``): the oracle of :mod:`evaluation.oracle`
  (ground truth with 50 mm joint noise, 4 cm height noise, 3 degree pose rotation noise, 1 % depth flips), or
* ``--lifter CHECKPOINT`` (implies ``--lifted lifter``): the learned lifter of :mod:`humancal.lifter` applied to
  the 2D detections only, in its crop frames (no ground truth is used in the lifting).

It reports the median and 90th percentile over all views of the focal, angle and position errors (after the
similarity alignment of :mod:`evaluation.camera_metrics`), the rig's metric scale error (which that alignment
removes), the reprojection error, how often the single-view focal was flagged ill-conditioned, and run times.
Views without upright people are deferred to the multi-view steps (``missing_upright="defer"``, as in the
pipeline).

Shelf: the real OpenPose detections grouped by ``humancal.datasets.shelf.load_shelf``; detections are matched
to the projected ground truth (``evaluation.detection_quality.evaluate_grouping``) only to build the stand-in
lifted poses (stand-in mode) and the reprojection metric's identities (both modes).

With the lifter, the sweep also reports the lifted poses' quality against the ground truth (evaluation only):
the fraction of detections lifted, the fraction scoring as upright, and the height error (bias and mean absolute
error) over all lifted detections of known people and over the upright ones.

``--extrinsics FIELD=V1,V2,...`` runs every value of one ``ExtrinsicsConfig`` field on each scene (generated and
lifted once) and summarises each value: how the library's defaults are chosen, on these synthetic scenes only.
With ``--shelf`` it takes a single value: Shelf is measured, never used to choose.

Usage::

    python scripts/calibration_sweep.py --scenes 30 --out .humancal/sweeps/calibration
    python scripts/calibration_sweep.py --scenes 0 --shelf      # Shelf only
    python scripts/calibration_sweep.py --scenes 30 --shelf --lifter .humancal/artifacts/lifter_checkpoint.pt \
        --out .humancal/sweeps/calibration_lifter
    python scripts/calibration_sweep.py --scenes 30 --lifter shipped --extrinsics shape_std_m=0.05,0.1,0.2
"""

from __future__ import annotations

import os

# The calibration works on many small matrices (69 x 69 point blocks, a few hundred unknowns): multi-threaded
# BLAS only adds overhead there, and on a busy 2-core machine it made the extrinsics 2-3 times slower.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from evaluation.camera_metrics import camera_errors, reprojection_errors_per_view  # noqa: E402
from evaluation.oracle import stand_in_lifted_poses  # noqa: E402
from humancal.calibration import (  # noqa: E402
    CalibrationError,
    ExtrinsicsConfig,
    IntrinsicsConfig,
    estimate_extrinsics,
    estimate_intrinsics,
    plot_rigs,
)
from humancal.lifter import LiftedPoses  # noqa: E402
from humancal.tables.associations import Associations  # noqa: E402
from humancal.tables.detections import detections_to_dense  # noqa: E402

PAPER_SHELF = {"focal_error_pct": 8.15, "position_error_mm": 605.88, "angle_error_deg": 9.72,
               "reprojection_error_px": 44.94}
"""The paper's initialisation figures on Shelf (Huang et al. 2024)."""


def scene_config(index: int, seed0: int):
    """The ``index``-th random scene configuration of the sweep."""
    from humancal.synthetic import preset

    rng = np.random.default_rng([seed0, index])
    lo = float(rng.uniform(500, 2200))
    hi = float(min(lo + rng.uniform(100, 600), 2500))
    return preset(
        "demo",
        seed=int(seed0 * 1000 + index),
        num_people=int(rng.integers(2, 9)),
        num_views=int(rng.integers(3, 9)),
        num_frames=int(rng.integers(60, 151)),
        focal_range_px=(lo, hi),
        rig="arc" if index % 4 == 3 else "ring",
    )


def lift_with(lifter, detections_table: pd.DataFrame):
    """Dense detections and their learned-lifter poses (crop frames; 2D detections only), and the seconds taken."""
    from humancal.lifter import lift_detections

    t0 = time.perf_counter()
    dense = detections_to_dense(detections_table)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    return dense, lifted, time.perf_counter() - t0


def lift_quality(lifted: LiftedPoses, true_height_m: np.ndarray, config: IntrinsicsConfig) -> dict:
    """Evaluation only: lifted height error and upright scores against the truth (NaN truth = unknown person).

    Returns the height error (estimate - truth, metres) over all lifted detections of known people and over the
    upright candidates (``upright_score >= config.upright_threshold``), and the fraction of such candidates.
    """
    known = lifted.valid & np.isfinite(true_height_m)
    err = lifted.height_m - true_height_m
    up = known & (lifted.upright_score >= config.upright_threshold)
    out = {"lifted_fraction": float(lifted.valid.mean()), "upright_fraction": float(up.sum() / max(known.sum(), 1))}
    for name, m in (("all", known), ("upright", up)):
        if m.any():
            out[f"height_bias_{name}_m"] = float(np.median(err[m]))
            out[f"height_mae_{name}_m"] = float(np.mean(np.abs(err[m])))
    return out


def _scene_person_ids(scene, dense) -> np.ndarray:
    """Ground-truth person of every dense detection row of a synthetic scene (-1: false positive)."""
    d = scene.detector
    return Associations(d.frame, d.view, scene.det_id, d.person_id).person_of_detections(dense)


def calibrate(detections, lifted, image_size_px, intrinsics_config, extrinsics_config=None):
    """Intrinsics then extrinsics; returns (intrinsics, extrinsics, seconds per stage)."""
    t0 = time.perf_counter()
    intrinsics = estimate_intrinsics(detections, lifted, image_size_px, intrinsics_config)
    t1 = time.perf_counter()
    extrinsics = estimate_extrinsics(detections, lifted, intrinsics, extrinsics_config)
    t2 = time.perf_counter()
    return intrinsics, extrinsics, {"intrinsics_s": t1 - t0, "extrinsics_s": t2 - t1}


def view_rows(name, intrinsics, extrinsics, gt_cameras, detections_table, associations, times):
    """One row per view with the errors of the result and of the single-view focal."""
    err = camera_errors(extrinsics.cameras, gt_cameras)
    reproj = reprojection_errors_per_view(extrinsics.cameras, detections_table, associations)
    floor = reprojection_errors_per_view(gt_cameras, detections_table, associations)
    rows = []
    for v, (est, gt) in enumerate(zip(intrinsics, gt_cameras)):
        f_gt = float(np.sqrt(gt.K[0, 0] * gt.K[1, 1]))
        rows.append({
            "scene": name, "view": v, "views": len(gt_cameras), "focal_gt_px": f_gt,
            "focal_error_pct": err["focal_error_pct"][v], "position_error_mm": err["position_error_mm"][v],
            "angle_error_deg": err["angle_error_deg"][v], "reprojection_error_px": reproj[v],
            # metric scale of the estimated rig relative to the truth (the alignment removes it from the errors)
            "scale_error_pct": 100.0 * (1.0 / err["alignment"].scale - 1.0),
            "reprojection_error_gt_cameras_px": floor[v], "single_view_status": est.status,
            "single_view_focal_error_pct": 100 * abs(est.fx_px - f_gt) / f_gt,
            "single_view_rel_uncertainty": est.focal_rel_uncertainty,
            "tilt_gt_deg": float(np.degrees(np.arcsin(np.clip(-gt.R_cam_from_world[2, 2], -1, 1)))),
            "final_focal_rel_std": float(extrinsics.diagnostics.per_view["focal_rel_std"][v]), **times,
        })
    return rows


def run_synthetic(n: int, seed0: int, config: IntrinsicsConfig, out: Path | None, lifter=None,
                  variants: dict[str, ExtrinsicsConfig] | None = None) -> pd.DataFrame:
    """The sweep over ``n`` seeded scenes; ``lifter`` (a loaded lifter) replaces the stand-in lifted poses.

    ``variants`` (name -> extrinsics settings, default: the library's) are all run on every scene (generated and
    lifted once); the rows carry the variant's name in column ``variant``.
    """
    variants = variants or {"default": ExtrinsicsConfig()}
    from humancal.body import BodyModel
    from humancal.synthetic import generate_scene

    body = BodyModel()
    rows = []
    for i in range(n):
        cfg = scene_config(i, seed0)
        t0 = time.perf_counter()
        scene = generate_scene(cfg, body, sequence=f"sweep_{i}")
        # the stand-in's random draws come first either way, so both modes see the same scene
        stand_in = stand_in_lifted_poses(scene, np.random.default_rng([seed0, i, 1]))
        gen_s = time.perf_counter() - t0
        extra = {"generate_s": gen_s}
        if lifter is None:
            detections, lifted = stand_in.detections, stand_in.lifted
        else:
            detections, lifted, extra["lift_s"] = lift_with(lifter, scene.detections)
            pid = _scene_person_ids(scene, detections)
            truth = np.where(pid >= 0, np.asarray(scene.height_m)[np.maximum(pid, 0)], np.nan)
            extra.update(lift_quality(lifted, truth, config))
        sizes = [(c.width_px, c.height_px) for c in scene.rig]
        for variant, extrinsics_config in variants.items():
            try:
                intr, extr, times = calibrate(detections, lifted, sizes, config, extrinsics_config)
            except CalibrationError as exc:
                print(f"scene {i} ({variant}): CalibrationError: {exc}")
                rows.append({"scene": f"sweep_{i}", "variant": variant, "failed": str(exc)})
                continue
            r = view_rows(f"sweep_{i}", intr, extr, list(scene.rig), scene.detections, scene.associations,
                          {**times, **extra})
            for row in r:
                row.update(people=cfg.num_people, frames=cfg.num_frames, rig=cfg.rig, variant=variant)
            rows += r
            df = pd.DataFrame(r)
            print(f"scene {i:2d} ({variant}): {cfg.num_people} people, {cfg.num_views} views ({cfg.rig}), "
                  f"{cfg.num_frames} frames, focal {cfg.focal_range_px[0]:.0f}-{cfg.focal_range_px[1]:.0f}: focal err "
                  f"max {df.focal_error_pct.max():.2f} %, angle max {df.angle_error_deg.max():.2f} deg, position max "
                  f"{df.position_error_mm.max():.0f} mm; {times['intrinsics_s']:.1f} + {times['extrinsics_s']:.1f} s",
                  flush=True)
        if out is not None and i == 0 and len(variants) == 1:
            plot_rigs(extr.cameras, list(scene.rig), _people_on_floor(extr.diagnostics),
                      out / "sweep_scene0_rigs.png", title="synthetic scene 0")
    return pd.DataFrame(rows)


def run_shelf(config: IntrinsicsConfig, out: Path | None, lifter=None,
              extrinsics_config: ExtrinsicsConfig | None = None) -> pd.DataFrame | None:
    """Shelf with the stand-in lifted poses, or with ``lifter`` (a loaded lifter) applied to the 2D detections."""
    from evaluation.detection_quality import evaluate_grouping
    from evaluation.oracle import canonical_from_shelf15, stand_in_from_matches
    from humancal.datasets.shelf import SHELF15_JOINTS, load_shelf
    from humancal.settings import DataRootError, dataset_dir

    try:
        root = dataset_dir("shelf_4dassoc")
    except DataRootError as exc:
        print(f"Shelf skipped: {exc}")
        return None
    t0 = time.perf_counter()
    shelf = load_shelf(root)
    matches = evaluate_grouping(shelf.detections, shelf.gt_poses, shelf.cameras, dataset="shelf").person_views
    matches = matches[matches["det_id"] >= 0]
    joints15 = np.transpose(shelf.gt_joints_world_m, (1, 0, 2, 3))  # (person, frame, 15, 3)
    top = joints15[..., SHELF15_JOINTS.index("top_head"), 2]
    ankle = np.minimum(joints15[..., SHELF15_JOINTS.index("left_ankle"), 2],
                       joints15[..., SHELF15_JOINTS.index("right_ankle"), 2])
    height = np.nanmedian(top - ankle, axis=1) + 0.07  # ankle height over the soles
    load_s = time.perf_counter() - t0
    extra = {"load_s": load_s}
    if lifter is None:
        stand_in = stand_in_from_matches(shelf.detections, shelf.cameras, canonical_from_shelf15(joints15), height,
                                         matches, np.random.default_rng(0))
        detections, lifted = stand_in.detections, stand_in.lifted
    else:
        detections, lifted, extra["lift_s"] = lift_with(lifter, shelf.detections)
        pid = Associations.from_table(matches.drop_duplicates(["frame", "view", "det_id"])).person_of_detections(
            detections)
        truth = np.where(pid >= 0, height[np.maximum(pid, 0)], np.nan)
        extra.update(lift_quality(lifted, truth, config))
    intr, extr, times = calibrate(detections, lifted, shelf.image_size_px, config.replace(missing_upright="defer"),
                                  extrinsics_config)
    assoc = matches[["sequence", "frame", "view", "det_id", "person_id"]]
    rows = view_rows("shelf", intr, extr, list(shelf.cameras), shelf.detections, assoc, {**times, **extra})
    if out is not None:
        what = "stand-in" if lifter is None else "learned-lifter"
        plot_rigs(extr.cameras, list(shelf.cameras), _people_on_floor(extr.diagnostics), out / "shelf_rigs.png",
                  title=f"Shelf ({what} lifted poses)")
    print(extr.diagnostics.per_view.to_string())
    return pd.DataFrame(rows)


def _people_on_floor(diagnostics) -> np.ndarray:
    """The people's floor positions, or their own positions when no floor was found."""
    return diagnostics.floor.floor_points_m if diagnostics.floor is not None else diagnostics.people_world_m


def extrinsics_variants(spec: str) -> dict[str, ExtrinsicsConfig]:
    """``"FIELD=V1,V2"`` -> {``"FIELD=V1"``: ExtrinsicsConfig(FIELD=V1), ...}, values typed like the default."""
    name, _, values = spec.partition("=")
    default = getattr(ExtrinsicsConfig(), name, _MISSING)
    if default is _MISSING or not values:
        raise SystemExit(f"--extrinsics {spec!r}: expected FIELD=V1[,V2...] with an ExtrinsicsConfig field")
    kind = type(default) if default is not None else float
    out = {}
    for text in values.split(","):
        value = None if text.lower() == "none" else kind(text)
        out[f"{name}={text}"] = ExtrinsicsConfig(**{name: value})
    return out


_MISSING = object()


def summary(df: pd.DataFrame) -> dict:
    ok = df.dropna(subset=["focal_error_pct"]) if "focal_error_pct" in df else df.iloc[:0]
    out = {"views": int(len(ok)), "scenes": int(ok["scene"].nunique()) if len(ok) else 0}
    for m in ("focal_error_pct", "angle_error_deg", "position_error_mm", "reprojection_error_px",
              "reprojection_error_gt_cameras_px", "single_view_focal_error_pct"):
        if m in ok and len(ok):
            out[m] = {"mean": float(ok[m].mean()), "median": float(ok[m].median()),
                      "p90": float(ok[m].quantile(0.9)), "max": float(ok[m].max())}
    if len(ok) and "scale_error_pct" in ok:
        scale = ok.groupby("scene")["scale_error_pct"].first()
        out["scale_error_pct_per_scene"] = {"median": float(scale.median()), "median_abs": float(scale.abs().median()),
                                            "p90_abs": float(scale.abs().quantile(0.9))}
    if len(ok):
        out["single_view_ill_conditioned_fraction"] = float((ok["single_view_status"] != "ok").mean())
        per_scene = ok.groupby("scene").first()
        out["seconds_per_scene"] = {"intrinsics_median": float(per_scene["intrinsics_s"].median()),
                                    "extrinsics_median": float(per_scene["extrinsics_s"].median()),
                                    "extrinsics_max": float(per_scene["extrinsics_s"].max())}
        if "lift_s" in per_scene:
            out["seconds_per_scene"]["lift_median"] = float(per_scene["lift_s"].median())
        quality = [c for c in per_scene.columns if c.startswith(("height_", "lifted_fraction", "upright_fraction"))]
        if quality:
            out["lifter_quality_scene_median"] = {c: float(per_scene[c].median()) for c in quality}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=30, help="number of synthetic scenes")
    parser.add_argument("--seed", type=int, default=0, help="sweep seed")
    parser.add_argument("--shelf", action="store_true", help="also run Shelf (skipped when its data is absent)")
    parser.add_argument("--plumb-top", default="shoulders", help="IntrinsicsConfig.plumb_top")
    parser.add_argument("--lifted", choices=("stand-in", "lifter"), default=None,
                        help="source of the lifted poses (default: 'lifter' when --lifter is given, else 'stand-in')")
    parser.add_argument("--lifter", type=Path, default=None,
                        help="learned lifter checkpoint (humancal.lifter), or 'shipped' for the packaged weights")
    parser.add_argument("--out", type=Path, default=None, help="folder for per-view CSVs, summary JSON, plots")
    parser.add_argument("--extrinsics", default=None, metavar="FIELD=V1[,V2...]",
                        help="ExtrinsicsConfig field and values to compare on the synthetic scenes (e.g. "
                             "shape_std_m=0.05,0.1,0.2; 'none' for None); with --shelf, a single value")
    args = parser.parse_args()
    variants = extrinsics_variants(args.extrinsics) if args.extrinsics else None
    if args.shelf and variants is not None and len(variants) > 1:
        parser.error("--shelf measures one setting: defaults are chosen on the synthetic scenes, never on Shelf")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    mode = args.lifted or ("lifter" if args.lifter is not None else "stand-in")
    if mode == "lifter" and args.lifter is None:
        parser.error("--lifted lifter needs --lifter CHECKPOINT")
    lifter = None
    if mode == "lifter":
        from humancal.lifter import load_lifter, shipped_checkpoint

        lifter = load_lifter(shipped_checkpoint() if str(args.lifter) == "shipped" else args.lifter)
    # a view without upright people gets its focal from the other views (what the pipeline does): the learned
    # lifter's upright score is 0 for steeply pitched cameras and for walking people, so some views have none
    config = IntrinsicsConfig(plumb_top=args.plumb_top, missing_upright="defer")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    result = {"lifted": mode, "extrinsics": args.extrinsics or "default"}
    if lifter is not None:
        result["lifter_checkpoint"] = args.lifter.name
    if args.scenes > 0:
        df = run_synthetic(args.scenes, args.seed, config, args.out, lifter, variants)
        if variants is None or len(variants) == 1:
            result["synthetic"] = summary(df)
        else:
            result["synthetic"] = {v: summary(df[df["variant"] == v]) for v in variants}
        if args.out is not None:
            df.to_csv(args.out / "synthetic_views.csv", index=False)
    if args.shelf:
        shelf = run_shelf(config, args.out, lifter, next(iter(variants.values())) if variants else None)
        if shelf is not None:
            means = {m: float(shelf[m].mean()) for m in PAPER_SHELF}
            quality = {c: float(shelf[c].iloc[0]) for c in shelf.columns
                       if c.startswith(("height_", "lifted_fraction", "upright_fraction"))}
            if quality:
                result["shelf_lifter_quality"] = quality
            result["shelf_scale_error_pct"] = float(shelf["scale_error_pct"].iloc[0])
            result["shelf"] = {"mean_over_views": means, "paper_init": PAPER_SHELF,
                               "reprojection_error_gt_cameras_px": float(shelf["reprojection_error_gt_cameras_px"].mean()),
                               "per_view": shelf.to_dict("records")}
            if args.out is not None:
                shelf.to_csv(args.out / "shelf_views.csv", index=False)
    print(json.dumps({k: (v if k != "shelf" else {kk: vv for kk, vv in v.items() if kk != "per_view"})
                      for k, v in result.items()}, indent=2))
    if args.out is not None:
        (args.out / "summary.json").write_text(json.dumps(result, indent=2, default=str))


if __name__ == "__main__":
    main()
