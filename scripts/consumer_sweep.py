"""Consumer-rig sweep of the calibration: seeded synthetic scenes filmed with phones, action cameras and webcams
(lens distortion, principal points off centre, fx != fy, unsynchronised videos at mixed frame rates), with learned
lifters of several training seeds; run and scored like ``scripts/stress_sweep.py`` (its lifters, blocking checks,
alignment on the trusted views and silent failures, imported from it and from ``scripts/sweep_scoring.py``).

Scene ``i`` is of family ``FAMILIES[i % 3]`` and draws from ``numpy.random.default_rng([seed, i])``:

* ``phone``: 5-10 phones on a ring (far apart: 3.5-6 m area), portrait (1080x1920) two scenes in three, else landscape;
  |k1| <= 0.1, principal points up to 5 % of the image off centre, fy / fx within 2 %, started by hand (time offsets
  up to +-2 s), 30 or 60 fps each;
* ``action_cam``: 5-8 action cameras (1920x1080), k1 -0.3 +- 0.05, k2 0.1 +- 0.03, 100-120 degrees across the image,
  principal points up to 2 % off, offsets up to +-2 s, 25/30/50/60 fps each;
* ``webcam``: 5-8 webcams (1280x720), 60-80 degrees across, k1 in [-0.1, 0.05], principal points up to 3 % off, fy / fx
  within 1 %, offsets up to +-0.5 s, 30 fps;

people seated in half the scenes (else ``mixed`` or ``low``), 2-4 of them, 20-60 frames of the 30 fps reference clock
(each view films that duration at its own rate). Scene ``i`` is lifted with lifter ``(i // 3) % L`` of the ``L`` given.

Time offsets. If ``humancal.sync`` exists, ``humancal.sync.estimate_time_offsets(detections, view_fps, lifter=...)``
(each view's offset in seconds, the reference time of its frame 0; NaN for a view it finds ambiguous) is scored against
the truth, and the calibration gets the detections moved onto the reference clock with the estimates (an ambiguous view
as filmed). Without it the offsets are NaN, and the calibration gets the detections as filmed (each view's own frame
numbers: unsynchronised), unless ``--oracle-sync``:
then each view's frames nearest in time to the reference frames, relabelled with them, using the TRUE offsets and frame
rates (:func:`humancal.synthetic.clocks.to_reference_frames`; for a view at the reference rate a shift by its true
integer frame offset). The summary says which mode ran. ``--interpolate``: each view's people at the reference
frames' times, blended between its two frames around each (``to_reference_frames(..., interpolate=True)``), with
the true offsets or the estimated ones.

Lens and principal point. The calibration's cameras are read as they come (``Camera.distortion``, ``Camera.K``): k1 / k2
count as estimated where they are not 0, a principal point where it is not the image centre; their errors against the
truth are in ``views.csv`` either way, the summary's figures cover the estimated ones only.

Per view: focal error %, angle error deg, position error mm (``evaluation.camera_metrics``), k1 / k2 error, principal
point error px, time offset error in the view's frames (``exact``: within half a frame). Every scene's result is written
to ``OUT/scenes/`` as it finishes (a killed sweep resumes); ``OUT/summary.md`` / ``summary.json``, ``OUT/views.csv``
(``scenes_oracle_sync/``, ``summary_oracle_sync.md`` ... with ``--oracle-sync``; ``--lens`` and ``--principal-point``
add their settings to the names).

    python scripts/consumer_sweep.py --scenes 60 --lifters shipped,seed1.pt,seed2.pt --out /tmp/consumer --jobs 2
    python scripts/consumer_sweep.py --scenes 6 --jobs 1 --out /tmp/consumer_small --oracle-sync
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import importlib.util  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import stress_sweep  # noqa: E402  (the calibration stress sweep, beside this script)
from sweep_scoring import (  # noqa: E402
    SILENT_ANGLE_DEG,
    SILENT_FOCAL_PCT,
    calibrate_scene,
    quantiles,
    run_jobs,
    score_calibration,
    sweep_arguments,
)

FAMILIES = ("phone", "action_cam", "webcam")
"""Scene ``i`` is of family ``FAMILIES[i % 3]``."""
_CENTRE_TOL_PX = 1e-6
"""A principal point within this of the image centre counts as not estimated."""


def scene_config(index: int, seed: int):
    """The ``index``-th scene configuration and its description (the drawn factors, in the columns
    ``stress_sweep.summarise`` groups by)."""
    from humancal.synthetic import preset

    rng = np.random.default_rng([seed, index])
    family = FAMILIES[index % 3]
    behaviour = str(rng.choice(["seated", "mixed", "low"], p=[0.5, 0.3, 0.2]))
    people = int(rng.integers(2, 5))
    frames = int(rng.integers(20, 61))
    area = (float(rng.uniform(4.0, 6.0)), float(rng.uniform(3.5, 5.0)))
    common = dict(seed=int(seed * 100_000 + index), num_people=people, num_frames=frames, behaviour=behaviour,
                  area_size_m=area, rig="ring")
    if family == "phone":
        views = int(rng.integers(5, 11))
        portrait = bool(rng.random() < 2 / 3)
        size = (1080, 1920) if portrait else (1920, 1080)
        config = preset("phone", num_views=views, image_size_px=size, **common)
    elif family == "action_cam":
        views, portrait, size = int(rng.integers(5, 9)), False, (1920, 1080)
        config = preset("action_cam", num_views=views, principal_point_offset_max_frac=0.02,
                        focal_aspect_range=(0.99, 1.01), time_offset_range_s=(-2.0, 2.0),
                        view_fps_choices=(25.0, 30.0, 50.0, 60.0), **common)
    else:
        views, portrait, size = int(rng.integers(5, 9)), False, (1280, 720)
        config = preset("demo", num_views=views, image_size_px=size, horizontal_fov_range_deg=(60.0, 80.0),
                        distortion_k1_range=(-0.1, 0.05), principal_point_offset_max_frac=0.03,
                        focal_aspect_range=(0.99, 1.01), time_offset_range_s=(-0.5, 0.5),
                        camera_height_range_m=(1.0, 2.2), **common)
    return config, {"family": family, "behaviour": behaviour, "people": people, "views": views, "frames": frames,
                    "rig": "ring", "image": f"{size[0]}x{size[1]}", "portrait": portrait, "cameras": family,
                    "distortion": True, "far_views": 0}


def _estimate_offsets(detections: pd.DataFrame, view_fps: np.ndarray, lifter) -> tuple[np.ndarray, str]:
    """Each view's estimated time offset, seconds, relative to view 0 (``humancal.sync.estimate_time_offsets``; NaN for
    the views it calls ambiguous, and for all without ``humancal.sync``), and a note on what ran."""
    if importlib.util.find_spec("humancal.sync") is None:
        return np.full(len(view_fps), np.nan), "not estimated: humancal.sync missing"
    from humancal.sync import estimate_time_offsets

    estimate = estimate_time_offsets(detections, view_fps, lifter=lifter)
    offsets = np.asarray(estimate.offset_s, dtype=np.float64).reshape(-1)
    ambiguous = int((~np.isfinite(offsets)).sum())
    return offsets, "estimated" + (f", {ambiguous} view(s) ambiguous" if ambiguous else "")


def _lens_rows(estimated, truth, clocks: pd.DataFrame, offsets_s: np.ndarray) -> list[dict]:
    """Per view: k1 / k2 and principal point against the truth, and the time offset error in the view's frames."""
    rows = []
    for v, (est, true) in enumerate(zip(estimated, truth)):
        centre = np.array([est.width_px / 2.0, est.height_px / 2.0])
        pp_est, pp_true = est.K[:2, 2], true.K[:2, 2]
        fps, offset = float(clocks["fps"].iloc[v]), float(clocks["time_offset_s"].iloc[v])
        error_frames = abs(offsets_s[v] - offset) * fps
        rows.append({
            "k2": float(true.distortion[1]), "k1_est": float(est.distortion[0]), "k2_est": float(est.distortion[1]),
            "k1_estimated": bool(est.distortion[0] != 0.0), "k2_estimated": bool(est.distortion[1] != 0.0),
            "k1_abs_error": abs(float(est.distortion[0] - true.distortion[0])),
            "k2_abs_error": abs(float(est.distortion[1] - true.distortion[1])),
            "aspect": float(true.K[1, 1] / true.K[0, 0]),
            "pp_offset_true_px": float(np.linalg.norm(pp_true - centre)),
            "pp_estimated": bool(np.linalg.norm(pp_est - centre) > _CENTRE_TOL_PX),
            "pp_error_px": float(np.linalg.norm(pp_est - pp_true)),
            "pp_error_x_px": float(pp_est[0] - pp_true[0]), "pp_error_y_px": float(pp_est[1] - pp_true[1]),
            "fps": fps, "time_offset_true_s": offset, "time_offset_est_s": float(offsets_s[v]),
            "time_offset_error_frames": float(error_frames),
            "time_offset_exact": bool(error_frames <= 0.5) if np.isfinite(error_frames) else None,
            "time_offset_estimated": bool(np.isfinite(offsets_s[v])),
        })
    return rows


def run_scene(index: int, seed: int, oracle_sync: bool, lens: dict | None = None, interpolate: bool = False) -> dict:
    """Generate, (synchronise,) lift, calibrate and score scene ``index``; returns {"scene": ..., "views": [...]}.
    ``lens``: ``ExtrinsicsConfig`` lens settings (``lens_models``, ``principal_point``) other than the defaults."""
    from humancal.calibration import ExtrinsicsConfig
    from humancal.lifter import lift_detections
    from humancal.synthetic import generate_scene
    from humancal.synthetic.clocks import to_reference_frames
    from humancal.tables.detections import detections_to_dense

    worker = stress_sweep._WORKER
    config, scene_row = scene_config(index, seed)
    lifter_seed, lifter = worker["lifters"][(index // 3) % len(worker["lifters"])]
    scene_row.update(scene=index, lifter_seed=lifter_seed)
    clock = time.perf_counter()
    scene = generate_scene(config, worker["body"], sequence=f"consumer_{index}")
    clocks = scene.view_clocks
    scene_row.update(generate_s=time.perf_counter() - clock, detections=int(len(scene.detections)),
                     reference_frames=int(scene.keypoints_world_m.shape[1]))
    fps, true_offsets = clocks["fps"].to_numpy(), clocks["time_offset_s"].to_numpy()
    clock = time.perf_counter()
    try:
        offsets, sync_note = _estimate_offsets(scene.detections, fps, lifter)
    except Exception as error:  # noqa: BLE001 - the estimator is another module's; its failure is recorded
        offsets, sync_note = np.full(len(fps), np.nan), f"sync failed: {type(error).__name__}: {error}"
    scene_row["sync_s"] = time.perf_counter() - clock
    if oracle_sync:
        detections = to_reference_frames(scene.detections, fps, true_offsets, config.fps, interpolate=interpolate)
        mode = "oracle"
    elif np.isfinite(offsets).any():  # a view the estimate leaves ambiguous keeps its frames as filmed (offset 0)
        known = np.where(np.isfinite(offsets), offsets, 0.0)
        detections = to_reference_frames(scene.detections, fps, known, config.fps, interpolate=interpolate)
        mode = "estimated" if np.isfinite(offsets).all() else "estimated, ambiguous views as filmed"
    else:
        detections, mode = scene.detections, "as filmed"
    scene_row.update(sync_mode=mode + (", interpolated" if interpolate else ""), sync_note=sync_note)
    clock = time.perf_counter()
    dense = detections_to_dense(detections)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    scene_row["lift_s"] = time.perf_counter() - clock
    sizes = [(c.width_px, c.height_px) for c in scene.rig]
    result = calibrate_scene(dense, lifted, sizes, ExtrinsicsConfig(repair_views=worker["repair"],
                                                                     scale_from_limbs=worker["limbs"], **(lens or {})),
                             scene_row)
    if result is None:
        return {"scene": scene_row, "views": []}
    fields, views = score_calibration(result, list(scene.rig), index, 0)
    scene_row.update(fields)
    for row, extra in zip(views, _lens_rows(result.cameras, scene.rig, clocks, offsets)):
        row.update(extra)
    return {"scene": scene_row, "views": views}


def _run_and_store(job: tuple[int, int, str, bool, dict, bool]) -> str:
    index, seed, folder, oracle, lens, interpolate = job
    result = run_scene(index, seed, oracle, lens, interpolate)
    path = Path(folder) / f"scene_{index:04d}.json"
    partial = path.with_suffix(".partial")
    partial.write_text(json.dumps(result, default=float))
    os.replace(partial, path)
    row = result["scene"]
    focal = (f", focal median {np.median([v['focal_error_pct'] for v in result['views']]):.2f} %"
             if result["views"] else f" ({row.get('message', '')[:120]})")
    return (f"scene {index:3d} {row['family']:10s} {row['behaviour']:6s} {row['views']:2d} views {row['frames']:2d} "
            f"frames {row['image']:9s} sync {row['sync_mode']}, lifter {row['lifter_seed']}: {row['outcome']}{focal} "
            f"({row.get('calibrate_s', 0):.1f} s)")


def summarise(scenes: pd.DataFrame, views: pd.DataFrame) -> dict:
    """The stress sweep's summary (outcomes, labels, silent failures, distributions by factor) and the consumer
    figures: focal median / p90, angle median, k1 / k2 / principal point errors where estimated, time offsets exact to
    the frame, the synchronisation mode."""
    out = stress_sweep.summarise(scenes, views)
    out["sync_modes"] = scenes["sync_mode"].value_counts().to_dict()
    out["sync_notes"] = scenes["sync_note"].value_counts().to_dict()
    if not len(views):
        return out
    consumer = {"focal_error_pct": quantiles(views["focal_error_pct"]),
                "angle_error_deg": quantiles(views["angle_error_deg"]),
                "position_error_mm": quantiles(views["position_error_mm"])}
    for name, flag in (("k1_abs_error", "k1_estimated"), ("k2_abs_error", "k2_estimated"), ("pp_error_px", "pp_estimated")):
        consumer[name] = quantiles(views.loc[views[flag].astype(bool), name])
        consumer[f"{flag}_views"] = int(views[flag].astype(bool).sum())
    others = views[views["view"] > 0]  # view 0 is the reference clock: exact by definition
    timed = others[others["time_offset_estimated"].astype(bool)]
    consumer["time_offset_views"] = int(len(others))
    consumer["time_offset_estimated_views"] = int(len(timed))
    # an ambiguous view (no estimate) counts as not exact; no estimate anywhere: None (NaN in the table)
    consumer["time_offset_exact_fraction"] = (float((timed["time_offset_exact"] == True).sum() / len(others))  # noqa: E712
                                              if len(timed) else None)
    consumer["time_offset_error_frames"] = quantiles(timed["time_offset_error_frames"])
    out["consumer"] = consumer
    return out


def _markdown(summary: dict, oracle: bool) -> str:
    c = summary.get("consumer", {})
    sync = ("the calibration got the detections moved onto the reference clock with the TRUE offsets and frame rates "
            "(--oracle-sync)" if oracle else "no oracle: the detections as filmed, or moved with the estimated offsets "
            "where humancal.sync gave them")
    lines = [f"# Consumer-rig sweep: {summary['scenes']} scenes, {summary['views']} views", "",
             f"Synchronisation: {sync}; modes per scene {summary['sync_modes']}; time offsets: "
             f"{summary['sync_notes']}.", ""]
    if c:
        f, a, p = c["focal_error_pct"], c["angle_error_deg"], c["position_error_mm"]
        exact = c["time_offset_exact_fraction"]
        lines += [
            "| figure | value |", "|---|---|",
            f"| focal error median / p90 | {f['median']:.2f} % / {f['p90']:.2f} % |",
            f"| angle error median / p90 | {a['median']:.2f} / {a['p90']:.2f} deg |",
            f"| position error median | {p['median']:.0f} mm |",
            "| k1 abs error median / p90 (estimated views) | "
            + (f"{c['k1_abs_error']['median']:.3f} / {c['k1_abs_error']['p90']:.3f} ({c['k1_estimated_views']} views) |"
               if c["k1_abs_error"]["n"] else "not estimated (the calibration's cameras have k1 = 0) |"),
            "| principal point error median (estimated views) | "
            + (f"{c['pp_error_px']['median']:.1f} px ({c['pp_estimated_views']} views) |"
               if c["pp_error_px"]["n"] else "not estimated (the calibration keeps the image centre) |"),
            "| time offsets exact to the frame (views 1..V-1) | "
            + (f"{100 * exact:.1f} % of {c['time_offset_views']} ({c['time_offset_estimated_views']} estimated; "
               f"error median {c['time_offset_error_frames']['median']:.2f} frames) |" if exact is not None
               else "not estimated: NaN |"),
            f"| silent failures (> {SILENT_FOCAL_PCT:g} % or > {SILENT_ANGLE_DEG:g} deg, no blocking check failed) | "
            f"{summary.get('silent_failures', 0)} views in scenes {summary.get('silent_failure_scenes', [])} |", ""]
    return "\n".join(lines) + "\n" + stress_sweep._markdown(summary)


def main() -> None:
    parser = sweep_arguments(__doc__.splitlines()[0], scenes=60)
    parser.add_argument("--lens", default=None, help="radial lens models compared by the calibration, comma-separated "
                        "(default: the calibration's, k1); e.g. pinhole")
    parser.add_argument("--principal-point", default=None, choices=("centre", "estimate", "auto"),
                        help="the calibration's principal point setting (default: its own, centre)")
    parser.add_argument("--max-k1-std", type=float, default=None,
                        help="the calibration's lens_max_k1_std (default: its own)")
    parser.add_argument("--oracle-sync", action="store_true",
                        help="feed the calibration the detections put on the reference clock with the TRUE time offsets")
    parser.add_argument("--interpolate", action="store_true",
                        help="blend each view's detections between frames at the reference frames' times")
    args = parser.parse_args()
    specs = [s.strip() for s in args.lifters.split(",") if s.strip()]
    for spec in specs:
        if spec != "shipped" and not Path(spec).is_file():
            parser.error(f"--lifters: {spec} is not a file (nor 'shipped')")
    lens = {}
    if args.lens:
        lens["lens_models"] = tuple(m.strip() for m in args.lens.split(","))
    if args.principal_point:
        lens["principal_point"] = args.principal_point
    if args.max_k1_std is not None:
        lens["lens_max_k1_std"] = args.max_k1_std
    # the modes never mix their results
    suffix = ("_oracle_sync" if args.oracle_sync else "") + ("_interpolated" if args.interpolate else "") + "".join(
        f"_{k}_{'-'.join(v) if isinstance(v, tuple) else v}" for k, v in lens.items())
    folder = args.out / f"scenes{suffix}"
    folder.mkdir(parents=True, exist_ok=True)
    indices = [int(i) for i in args.only.split(",")] if args.only else list(range(args.scenes))
    todo = [i for i in indices if not (folder / f"scene_{i:04d}.json").exists()]
    print(f"{len(indices) - len(todo)} scenes already done in {folder}; {len(todo)} to run", flush=True)
    run_jobs([(i, args.seed, str(folder), args.oracle_sync, lens, args.interpolate) for i in todo], _run_and_store,
             stress_sweep._init_worker, (specs,), args.jobs)
    results = [json.loads((folder / f"scene_{i:04d}.json").read_text()) for i in indices]
    scenes = pd.DataFrame([r["scene"] for r in results])
    views = pd.DataFrame([v for r in results for v in r["views"]])
    summary = summarise(scenes, views)
    scenes.drop(columns=["traceback"], errors="ignore").to_csv(args.out / f"scenes{suffix}.csv", index=False)
    views.to_csv(args.out / f"views{suffix}.csv", index=False)
    (args.out / f"summary{suffix}.json").write_text(json.dumps(summary, indent=2, default=str))
    (args.out / f"summary{suffix}.md").write_text(_markdown(summary, args.oracle_sync))
    print(_markdown(summary, args.oracle_sync))
    for r in results:
        if r["scene"].get("traceback"):
            print(f"scene {r['scene']['scene']} crashed:\n{r['scene']['traceback']}")


if __name__ == "__main__":
    main()
