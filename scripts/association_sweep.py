"""Synthetic sweep of the association: who is who on seeded scenes, with the self-calibrated and the true cameras.

Each scene ``i`` draws its cameras, images, lenses and behaviour as the calibration stress sweep does
(``scripts/stress_sweep.py``, :func:`stress_sweep.scene_config`), then, from ``numpy.random.default_rng([seed,
10_000 + i])``:

* 2-8 people and 3-8 views; 150-450 frames (5-15 s);
* a capture area of 2.5-5 m^2 per person (at least 12 m^2): people pass close by and cross each other's paths;
* people out of every view for a while (``SceneConfig.out_of_view_spells`` 0.2-1: 1-4 s spells, some at the
  start or the end: entering late, leaving early);
* the default detector noise (jitter, missed joints and people, false positives, left-right flips);
* behaviour ``mixed`` for six scenes in eight, ``seated`` and ``low`` for one each.

``--ring`` more scenes have 31 views on a full ring (named ``ring_<k>``, drawn the same way otherwise).

Every scene is lifted with the shipped lifter and calibrated from the detections alone (intrinsics and
extrinsics, as the stress sweep). Four associations follow: ``association`` (the default
:class:`~humancal.association.TrackingConfig`) and ``epipolar_only`` (the geometric affinity alone) with the
estimated cameras, and both again with the true cameras (``*_gt_cameras``). Each is scored against the true
identities (:func:`evaluation.association_metrics.identity_metrics`): pairwise precision/recall/F1, idf1, id
switches, false positives rejected, estimated minus true number of people, seconds. Per true person, the ids
holding its detections (and per estimated id, the true people in it) say what merged or split.

Every scene's result is written to ``OUT/scenes/`` as it finishes (a killed sweep resumes where it stopped);
``OUT/summary.md``, ``OUT/summary.json``, ``OUT/methods.csv`` (one row per scene and method) and
``OUT/association_sweep.png`` (F1 distribution and people-count errors per method) summarise.

    python scripts/association_sweep.py --scenes 32 --ring 1 --jobs 2 --out association_sweep_out
"""

from __future__ import annotations

import os

# many small matrices: multi-threaded BLAS only adds overhead (and the sweep runs scenes in parallel)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import multiprocessing  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import stress_sweep  # noqa: E402  (the calibration stress sweep, beside this script)

METHODS = ("association", "epipolar_only", "association_gt_cameras", "epipolar_only_gt_cameras")
BEHAVIOURS = ("mixed", "mixed", "mixed", "low", "mixed", "mixed", "seated", "mixed")
"""Scene ``i`` has behaviour ``BEHAVIOURS[i % 8]``."""
RING_VIEWS = 31
_F1_FLOOR = 1e-4


def scene_name(index: int, ring: bool) -> str:
    return f"ring_{index:02d}" if ring else f"scene_{index:04d}"


def scene_config(index: int, seed: int, ring: bool = False):
    """The configuration of scene ``index`` (ring scenes: 31 views on a full ring) and its drawn factors."""
    rng = np.random.default_rng([seed, 10_000 + index, int(ring)])
    views = RING_VIEWS if ring else int(rng.integers(3, 9))
    people = int(rng.integers(2, 9))
    frames = int(rng.integers(150, 451))
    area_m2 = max(12.0, people * float(rng.uniform(2.5, 5.0)))
    aspect = float(rng.uniform(1.0, 1.4))
    area = (round(float(np.sqrt(area_m2 * aspect)), 2), round(float(np.sqrt(area_m2 / aspect)), 2))
    spells = round(float(rng.uniform(0.2, 1.0)), 2)
    behaviour = BEHAVIOURS[index % len(BEHAVIOURS)]
    base, described = stress_sweep.scene_config(index + (1000 if ring else 0), seed, views)
    changes = dict(num_people=people, num_frames=frames, area_size_m=area, out_of_view_spells=spells,
                   behaviour=behaviour)
    if ring:
        changes["rig"] = "ring"
    config = base.replace(**changes)
    described.update(people=people, frames=frames, views=views, behaviour=behaviour, rig=config.rig,
                     area_m2=round(area[0] * area[1], 1), out_of_view_spells=spells)
    return config, described


def _structure(confusion: pd.DataFrame) -> dict:
    """Which estimated ids hold each true person's detections, and which true people each estimated id holds
    (detection counts, largest three; -1: rejected / false positive), from ``identity_confusion``."""
    def top(by: str, other: str) -> dict:
        return {str(key): {str(o): int(n) for o, n in zip(group[other].head(3), group["detections"].head(3))}
                for key, group in confusion.groupby(by)}
    return {"true_to_est": top("true", "est"), "est_to_true": top("est", "true")}


def run_scene(index: int, seed: int, ring: bool) -> dict:
    """Generate, lift, calibrate, associate four ways and score scene ``index``."""
    from evaluation.association_metrics import identity_confusion, identity_metrics
    from evaluation.camera_metrics import camera_errors
    from humancal.association import AffinityConfig, TrackingConfig, associate, to_associations_table
    from humancal.calibration import CalibrationError, IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
    from humancal.camera import CameraRig
    from humancal.lifter import lift_detections
    from humancal.synthetic import generate_scene
    from humancal.tables.detections import detections_to_dense

    config, row = scene_config(index, seed, ring)
    name = scene_name(index, ring)
    row.update(scene=name, index=index, ring=ring)
    clock = time.perf_counter()
    scene = generate_scene(config, stress_sweep._WORKER["body"], sequence=name)
    detected = scene.detector.detected.any(axis=0)  # (P, F): seen by some view
    positions = scene.root_translation_m[..., :2]
    close = np.linalg.norm(positions[:, None] - positions[None], axis=-1) < 1.0
    pairs = np.triu(np.ones(close.shape[:2], bool), 1)
    row.update(generate_s=time.perf_counter() - clock, detections=int(scene.detector.num_detections),
               false_positives=int((scene.detector.person_id < 0).sum()),
               flips=int(scene.detector.flipped.sum()),
               out_of_view_fraction=float(1.0 - detected.mean()),
               close_pass_fraction=float(close[pairs].any(axis=0).mean()) if pairs.any() else 0.0)
    clock = time.perf_counter()
    dense = detections_to_dense(scene.detections)
    lifter = stress_sweep._WORKER["lifters"][0][1]
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    row["lift_s"] = time.perf_counter() - clock
    clock = time.perf_counter()
    cameras = None
    try:
        intrinsics = estimate_intrinsics(dense, lifted, [(c.width_px, c.height_px) for c in scene.rig],
                                         IntrinsicsConfig(missing_upright="defer"))
        cameras = estimate_extrinsics(dense, lifted, intrinsics).cameras
        errors = camera_errors(cameras, list(scene.rig))
        row.update(calibration="ok", focal_error_pct_median=float(np.median(errors["focal_error_pct"])),
                   focal_error_pct_max=float(np.max(errors["focal_error_pct"])),
                   angle_error_deg_median=float(np.median(errors["angle_error_deg"])),
                   angle_error_deg_max=float(np.max(errors["angle_error_deg"])),
                   position_error_mm_median=float(np.median(errors["position_error_mm"])))
    except CalibrationError as error:
        row.update(calibration="calibration_error", message=str(error))
    except Exception as error:  # noqa: BLE001 - a crash is recorded with its traceback; the true cameras still run
        row.update(calibration="crash", message=f"{type(error).__name__}: {error}", traceback=traceback.format_exc())
    row["calibrate_s"] = time.perf_counter() - clock

    rigs = {"": cameras, "_gt_cameras": list(scene.rig)}
    affinities = {"association": AffinityConfig(), "epipolar_only": AffinityConfig.epipolar_only()}
    methods = []
    for suffix, rig_cameras in rigs.items():
        for base, affinity in affinities.items():
            method = {"scene": name, "method": base + suffix}
            if rig_cameras is None:
                methods.append({**method, "outcome": "no_cameras"})
                continue
            clock = time.perf_counter()
            try:
                result = associate(dense, lifted, CameraRig.from_cameras(rig_cameras),
                                   TrackingConfig(affinity=affinity))
            except Exception as error:  # noqa: BLE001 - counted as a crash of this method
                methods.append({**method, "outcome": "crash", "message": f"{type(error).__name__}: {error}",
                                "traceback": traceback.format_exc()})
                continue
            seconds = time.perf_counter() - clock
            table = to_associations_table(result, name)
            metrics = {r.metric: float(r.value) for r in identity_metrics(table, scene.associations)}
            method.update(outcome="ok", seconds=seconds, num_people_est=int(result.num_people),
                          num_people_true=int(scene.associations.loc[scene.associations["person_id"] >= 0,
                                                                     "person_id"].nunique()),
                          **metrics, structure=_structure(identity_confusion(table, scene.associations)))
            methods.append(method)
    return {"scene": row, "methods": methods}


def _run_and_store(job: tuple[int, int, bool, str]) -> str:
    index, seed, ring, folder = job
    result = run_scene(index, seed, ring)
    path = Path(folder) / f"{scene_name(index, ring)}.json"
    partial = path.with_suffix(".partial")
    partial.write_text(json.dumps(result, default=float))
    os.replace(partial, path)
    row = result["scene"]
    scores = ", ".join(f"{m['method']} F1 {m['pairwise_f1']:.3f} people {m['num_people_error']:+.0f}"
                       for m in result["methods"] if m["outcome"] == "ok")
    return (f"{row['scene']}: {row['people']} people, {row['views']} views, {row['frames']} frames, "
            f"{row['behaviour']}, calibration {row['calibration']} ({row['calibrate_s']:.0f} s); {scores}")


def _init_worker() -> None:
    stress_sweep._init_worker(["shipped"])


def summarise(scenes: pd.DataFrame, methods: pd.DataFrame) -> dict:
    """Per method: F1 and idf1 distributions, people-count errors, switches, false-positive rejection, seconds;
    and the association by scene factor."""
    out = {"scenes": int(len(scenes)), "calibration": scenes["calibration"].value_counts().to_dict()}
    per_method = {}
    for method in METHODS:
        rows = methods[methods["method"] == method]
        ok = rows[rows["outcome"] == "ok"]
        entry = {"scenes": int(len(rows)), "ok": int(len(ok))}
        if len(ok):
            f1 = ok["pairwise_f1"]
            error = ok["num_people_error"]
            entry.update(
                f1_median=float(f1.median()), f1_p10=float(f1.quantile(0.1)), f1_min=float(f1.min()),
                f1_mean=float(f1.mean()), scenes_f1_ge_098=int((f1 >= 0.98).sum()),
                precision_median=float(ok["pairwise_precision"].median()),
                recall_median=float(ok["pairwise_recall"].median()),
                idf1_median=float(ok["idf1"].median()), idf1_min=float(ok["idf1"].min()),
                id_switches_median=float(ok["id_switches"].median()), id_switches_total=int(ok["id_switches"].sum()),
                fp_rejection_median_pct=float(ok["fp_rejection_rate"].median()),
                people_right_share_pct=float(100.0 * (error == 0).mean()),
                people_error_counts={str(int(k)): int(v) for k, v in error.value_counts().sort_index().items()},
                seconds_median=float(ok["seconds"].median()), seconds_max=float(ok["seconds"].max()),
                worst=[{"scene": r.scene, "f1": float(r.pairwise_f1), "people_error": int(r.num_people_error)}
                       for r in ok.nsmallest(5, "pairwise_f1").itertuples()],
            )
        per_method[method] = entry
    out["methods"] = per_method
    merged = methods[methods["outcome"] == "ok"].merge(scenes, on="scene", suffixes=("", "_scene"))
    factors = {}
    for factor in ("behaviour", "views_bin", "people", "distortion", "cameras"):
        if factor == "views_bin":
            key = pd.cut(merged["views"], [2, 4, 6, 8, 31], labels=["3-4", "5-6", "7-8", "31"])
        else:
            key = merged[factor]
        table = merged.groupby([key, merged["method"]], observed=True).agg(
            scenes=("pairwise_f1", "size"), f1_median=("pairwise_f1", "median"),
            people_right_pct=("num_people_error", lambda e: 100.0 * float((e == 0).mean())))
        factors[factor] = {f"{k[0]}|{k[1]}": v for k, v in table.to_dict(orient="index").items()}
    out["by_factor"] = factors
    return out


def _markdown(summary: dict) -> str:
    lines = [f"# Association sweep: {summary['scenes']} scenes", "",
             f"Calibration: {summary['calibration']}", "",
             "| method | scenes | F1 median | F1 p10 | F1 min | precision median | recall median | idf1 median "
             "| right people count | id switches (total) | FP rejected median | seconds median |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for method, m in summary["methods"].items():
        if not m.get("ok"):
            lines.append(f"| {method} | 0 of {m['scenes']} | | | | | | | | | | |")
            continue
        lines.append(f"| {method} | {m['ok']} | {m['f1_median']:.4f} | {m['f1_p10']:.4f} | {m['f1_min']:.4f} | "
                     f"{m['precision_median']:.4f} | {m['recall_median']:.4f} | {m['idf1_median']:.4f} | "
                     f"{m['people_right_share_pct']:.0f} % | {m['id_switches_total']} | "
                     f"{m['fp_rejection_median_pct']:.1f} % | {m['seconds_median']:.2f} |")
    lines.append("")
    for method, m in summary["methods"].items():
        if m.get("ok"):
            lines.append(f"- {method}: people count error {m['people_error_counts']}; worst: "
                         + ", ".join(f"{w['scene']} F1 {w['f1']:.3f} ({w['people_error']:+d})" for w in m["worst"]))
    lines.append("")
    for factor, table in summary["by_factor"].items():
        lines += [f"## by {factor}", "", f"| {factor} | method | scenes | F1 median | right people count |",
                  "|---|---|---|---|---|"]
        for key, v in table.items():
            value, method = key.split("|")
            lines.append(f"| {value} | {method} | {v['scenes']} | {v['f1_median']:.4f} | {v['people_right_pct']:.0f} % |")
        lines.append("")
    return "\n".join(lines) + "\n"


def _plot(methods: pd.DataFrame, path: Path) -> None:
    from humancal.plotting import pyplot, save_figure

    plt = pyplot()
    ok = methods[methods["outcome"] == "ok"]
    fig, (ax_f1, ax_people) = plt.subplots(1, 2, figsize=(12, 4.5))
    for method in METHODS:
        f1 = ok.loc[ok["method"] == method, "pairwise_f1"].to_numpy()
        if len(f1):  # 1 - F1 on a log axis: the scenes near 1 spread out (a perfect scene is drawn at 1e-4)
            miss = np.sort(np.maximum(1.0 - f1, _F1_FLOOR))
            ax_f1.step(miss, np.arange(1, len(miss) + 1) / len(miss), where="post",
                       label=f"{method} (median F1 {np.median(f1):.4f}, {len(f1)} scenes)")
    ax_f1.axvline(0.02, color="grey", linestyle=":", label="target F1 0.98")
    ax_f1.set_xscale("log")
    ax_f1.set_xlabel(f"1 - pairwise F1 of a scene (perfect scenes at {_F1_FLOOR:g})")
    ax_f1.set_ylabel("fraction of scenes")
    ax_f1.set_title("Pairwise F1 per scene")
    ax_f1.grid(True, alpha=0.3)
    ax_f1.legend(fontsize=8, loc="lower right")
    errors = ok.pivot(index="scene", columns="method", values="num_people_error")
    values = sorted({int(v) for v in errors.stack().dropna()} | {0})
    grid = np.arange(min(values), max(values) + 1)
    width = 0.8 / len(METHODS)
    for k, method in enumerate(METHODS):
        if method not in errors:
            continue
        counts = errors[method].dropna().astype(int).value_counts().reindex(grid, fill_value=0)
        ax_people.bar(grid + (k - (len(METHODS) - 1) / 2) * width, counts.to_numpy(), width, label=method)
    ax_people.set_xticks(grid)
    ax_people.set_xlabel("estimated minus true number of people")
    ax_people.set_ylabel("scenes")
    ax_people.set_title("People-count error")
    ax_people.grid(True, axis="y", alpha=0.3)
    ax_people.legend(fontsize=8)
    fig.suptitle("Association sweep: synthetic scenes, self-calibrated and true cameras")
    fig.tight_layout()
    save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=32, help="scenes with 3-8 views")
    parser.add_argument("--ring", type=int, default=1, help="more scenes with 31 views on a ring")
    parser.add_argument("--seed", type=int, default=0, help="sweep seed")
    parser.add_argument("--out", type=Path, required=True, help="folder for the per-scene results and summaries")
    parser.add_argument("--jobs", type=int, default=1, help="scenes run in parallel (one process each)")
    parser.add_argument("--only", default=None, help="comma-separated scene names (e.g. scene_0003,ring_00)")
    args = parser.parse_args()
    folder = args.out / "scenes"
    folder.mkdir(parents=True, exist_ok=True)
    jobs = [(i, args.seed, False, str(folder)) for i in range(args.scenes)]
    jobs += [(i, args.seed, True, str(folder)) for i in range(args.ring)]
    if args.only:
        wanted = {s.strip() for s in args.only.split(",")}
        jobs = [j for j in jobs if scene_name(j[0], j[2]) in wanted]
    names = [scene_name(j[0], j[2]) for j in jobs]
    # the 31-view scenes take longest: start them first
    todo = sorted((j for j in jobs if not (folder / f"{scene_name(j[0], j[2])}.json").exists()), key=lambda j: not j[2])
    print(f"{len(jobs) - len(todo)} scenes already done in {folder}; {len(todo)} to run", flush=True)
    start = time.perf_counter()
    if todo:
        if args.jobs > 1:
            with multiprocessing.get_context("spawn").Pool(args.jobs, _init_worker) as pool:
                for done, line in enumerate(pool.imap_unordered(_run_and_store, todo), 1):
                    print(f"[{done}/{len(todo)} {time.perf_counter() - start:.0f} s] {line}", flush=True)
        else:
            _init_worker()
            for done, job in enumerate(todo, 1):
                line = _run_and_store(job)
                print(f"[{done}/{len(todo)} {time.perf_counter() - start:.0f} s] {line}", flush=True)
    results = [json.loads((folder / f"{name}.json").read_text()) for name in names]
    scenes = pd.DataFrame([r["scene"] for r in results])
    methods = pd.DataFrame([m for r in results for m in r["methods"]])
    summary = summarise(scenes, methods)
    scenes.drop(columns=["traceback"], errors="ignore").to_csv(args.out / "scenes.csv", index=False)
    methods.drop(columns=["structure", "traceback"], errors="ignore").to_csv(args.out / "methods.csv", index=False)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    (args.out / "summary.md").write_text(_markdown(summary))
    _plot(methods, args.out / "association_sweep.png")
    print(_markdown(summary))
    for r in results:
        for item in [r["scene"], *r["methods"]]:
            if item.get("traceback"):
                print(f"{r['scene']['scene']} {item.get('method', 'calibration')} crashed:\n{item['traceback']}")


if __name__ == "__main__":
    main()
