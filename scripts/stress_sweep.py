"""Stress sweep of the camera initialisation: seeded synthetic scenes drawn wide, with learned lifters of several
training seeds; failures reported by kind, errors by scene kind.

Each scene ``i`` of the wide family draws (from ``numpy.random.default_rng([seed, i])``):

* behaviour: ``mixed`` (people walk, stand, turn, gesture, sometimes crouch) for half the scenes, ``seated``
  (everyone sits all along) and ``low`` (mostly sitting, crouching, bending) for a quarter each;
* 2-6 people; 2-31 views (2: 10 %, 3-8: 55 %, 9-20: 20 %, 21-31: 15 %) on a ring (an arc for one in four);
* 20-300 frames (log-uniform); a focal range inside 500-2500 px;
* images landscape (1920x1080, 1280x720) or, one scene in four, portrait (1080x1920, 720x1280);
* cameras: ordinary (1.5-4 m high, looking at the area centre), steeply down (45-70 degrees below the
  horizon) or near the horizon (0-5 degrees);
* one scene in three with radial lens distortion, k1 drawn per camera in [-0.15, 0.05] (the calibration takes
  k1 where held-out frames support it: ``ExtrinsicsConfig.lens_models``).

Scene ``i`` is lifted with lifter ``(i // 4) % L`` of the ``L`` given (``--lifters``), so every behaviour meets
every lifter. The lifted poses come from the 2D detections only; the ground truth is used for the errors alone.

Outcome of each scene, by kind: ``ok``; ``calibration_error`` (a :class:`~humancal.calibration.CalibrationError`,
the stage in its message: a labelled refusal); ``crash`` (any other exception: a bug). Labels a calibrated scene
can carry: ``world_frame`` ``camera_0`` (no floor found), views placed again by the view repair, and the blocking
checks of the pipeline's ``extrinsics`` asset it fails (``cameras_valid``, ``focal_plausible``, ``rig_geometry``,
``people_plausible``, ``views_agree``, ``focal_constrained``): ``humancal update`` would stop there (exit 1), naming
the views. A **silent failure** is a view whose focal error exceeds 5 % or whose angle error exceeds 3 deg in a
scene that fails no blocking check (``humancal update`` would exit 0): the thing this sweep exists to rule out.
Scenes ``2, 5, 8, ...`` are of the studio family (what broke on real studio captures: people mostly seated, 5 or
10 cameras over a dome or a ring, 20-60 frames, in two scenes of five one camera far back with a zoom lens);
the others of the wide family drawn as listed above. For this judgement the
errors of a view are measured after an alignment fitted on the views whose focal is ``ok`` only
(``*_trusted`` columns): a flagged view placed metres off can drag the alignment of a small rig, and with it the
angles of the good views, by tens of degrees (a 4-view arc: 174 deg with the flagged view in the alignment, 3-4 deg
without); when three views are left, a point ahead on each optical axis joins their centres in that alignment
(three centres leave its rotation to the small errors of their triangle's shape; two views get these points in
any alignment). The distributions use the alignment of all views.

Every scene's result is written to ``OUT/scenes/`` as it finishes: a killed sweep resumes where it stopped.
``OUT/summary.md`` and ``OUT/summary.json`` hold the distributions, ``OUT/views.csv`` every view,
``OUT/focal_error_cdf.png`` the error distributions by behaviour.

    python scripts/stress_sweep.py --scenes 120 --lifters shipped,seed1.pt,seed2.pt --out /tmp/stress --jobs 2
    python scripts/stress_sweep.py --scenes 6 --views 31 --lifters shipped,seed1.pt,seed2.pt --out /tmp/stress31
"""

from __future__ import annotations

import os

# many small matrices: multi-threaded BLAS only adds overhead (and the sweep runs scenes in parallel)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from sweep_scoring import (  # noqa: E402,F401
    SILENT_ANGLE_DEG,
    SILENT_FOCAL_PCT,
    calibrate_scene,
    quantiles,
    run_jobs,
    score_calibration,
    sweep_arguments,
)

BEHAVIOURS = ("mixed", "mixed", "seated", "low")
"""Scene ``i`` has behaviour ``BEHAVIOURS[i % 4]``."""


def _wide_scene(rng: np.random.Generator, index: int, seed: int, views: int | None):
    """A scene of the wide family: everything drawn over broad ranges (the sweep's first 102-scene design)."""
    from humancal.synthetic import preset

    behaviour = BEHAVIOURS[index % 4]
    drawn_views = int(rng.choice([2, int(rng.integers(3, 9)), int(rng.integers(9, 21)), int(rng.integers(21, 32))],
                                 p=[0.1, 0.55, 0.2, 0.15]))
    views = views or drawn_views
    frames = int(round(np.exp(rng.uniform(np.log(20), np.log(300)))))
    people = int(rng.integers(2, 7))
    lo = float(rng.uniform(500, 2000))
    hi = float(min(lo + rng.uniform(100, 600), 2500))
    portrait = bool(rng.random() < 0.25)
    size = [(1920, 1080), (1280, 720)][int(rng.integers(2))]
    size = size[::-1] if portrait else size
    height_kind = str(rng.choice(["ordinary", "steep", "horizon"], p=[0.5, 0.25, 0.25]))
    pitch = {"ordinary": None, "steep": (45.0, 70.0), "horizon": (0.0, 5.0)}[height_kind]
    k1 = (-0.15, 0.05) if rng.random() < 1 / 3 else (0.0, 0.0)
    rig = "arc" if rng.random() < 0.25 else "ring"
    config = preset("demo", seed=int(seed * 100_000 + index), num_people=people, num_views=views, num_frames=frames,
                    focal_range_px=(lo, hi), image_size_px=size, camera_pitch_range_deg=pitch, rig=rig,
                    behaviour=behaviour, distortion_k1_range=k1)
    return config, {"family": "wide", "behaviour": behaviour, "people": people, "views": views, "frames": frames,
                    "rig": rig, "image": f"{size[0]}x{size[1]}", "portrait": portrait, "cameras": height_kind,
                    "distortion": k1 != (0.0, 0.0), "far_views": 0}


def _studio_scene(rng: np.random.Generator, index: int, seed: int, views: int | None):
    """A scene of the studio family: what broke on real studio captures (people mostly seated, 5 or 10 cameras
    spread over a dome from knee height to overhead, 20-60 frames, sometimes one camera far back with a zoom
    lens)."""
    from humancal.synthetic import preset

    behaviour = str(rng.choice(["seated", "mixed", "low"], p=[0.6, 0.25, 0.15]))
    views = views or int(rng.choice([5, 10]))
    frames = 20 if rng.random() < 0.5 else int(round(np.exp(rng.uniform(np.log(20), np.log(60)))))
    people = int(rng.integers(2, 6))
    rig = "dome" if rng.random() < 0.7 else "ring"
    far = int(rng.random() < 0.4)
    portrait = bool(rng.random() < 1 / 6)
    size = (1080, 1920) if portrait else (1920, 1080)
    area = np.array([rng.uniform(3.0, 5.0), rng.uniform(3.0, 4.0)])
    area = tuple(float(a) for a in area * max(1.0, np.sqrt(2.2 * people / area.prod())))  # 2 m^2 a person at least
    k1 = (-0.1, 0.0) if rng.random() < 0.25 else (0.0, 0.0)
    config = preset("demo", seed=int(seed * 100_000 + index), num_people=people, num_views=views, num_frames=frames,
                    focal_range_px=(1200.0, 1800.0), image_size_px=size, rig=rig, behaviour=behaviour,
                    distortion_k1_range=k1, area_size_m=area, far_views=far)
    return config, {"family": "studio", "behaviour": behaviour, "people": people, "views": views, "frames": frames,
                    "rig": rig, "image": f"{size[0]}x{size[1]}", "portrait": portrait, "cameras": rig,
                    "distortion": k1 != (0.0, 0.0), "far_views": far}


def scene_config(index: int, seed: int, views: int | None = None):
    """The ``index``-th scene configuration and its description (a dict of the drawn factors); ``views`` replaces
    the drawn number of views (the other draws stay the same). Scenes ``2, 5, 8, ...`` are of the studio family,
    the others of the wide family."""
    rng = np.random.default_rng([seed, index])
    if index % 3 == 2:
        return _studio_scene(rng, index, seed, views)
    return _wide_scene(rng, index, seed, views)


_WORKER: dict = {}


def _init_worker(lifter_specs: list[str], repair: bool = True, limbs: bool = True, lens: dict | None = None) -> None:
    import torch

    from humancal.body import BodyModel
    from humancal.lifter import load_lifter, shipped_checkpoint

    torch.set_num_threads(1)
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")
    _WORKER["body"] = BodyModel()
    lifters = []
    for spec in lifter_specs:
        checkpoint = shipped_checkpoint() if spec == "shipped" else torch.load(spec, map_location="cpu",
                                                                                weights_only=True)
        lifters.append((int(checkpoint["config"]["seed"]), load_lifter(checkpoint)))
    _WORKER["lifters"] = lifters
    _WORKER["repair"] = repair
    _WORKER["lens"] = lens or {}
    _WORKER["limbs"] = limbs


def run_scene(index: int, seed: int, views: int | None = None) -> dict:
    """Generate, lift, calibrate and score scene ``index``; returns {"scene": ..., "views": [...]}."""
    from humancal.calibration import ExtrinsicsConfig
    from humancal.lifter import lift_detections
    from humancal.synthetic import generate_scene
    from humancal.synthetic.activities import ACTIVITIES
    from humancal.tables.detections import detections_to_dense

    config, scene_row = scene_config(index, seed, views)
    lifter_seed, lifter = _WORKER["lifters"][(index // 4) % len(_WORKER["lifters"])]
    scene_row.update(scene=index, lifter_seed=lifter_seed)
    clock = time.perf_counter()
    scene = generate_scene(config, _WORKER["body"], sequence=f"stress_{index}")
    on_feet = np.isin(scene.activity, [ACTIVITIES.index(k) for k in ("walk", "turn", "stand", "gesture")])
    scene_row.update(generate_s=time.perf_counter() - clock, on_feet_fraction=float(on_feet.mean()),
                     detections=int(len(scene.detections)))
    clock = time.perf_counter()
    dense = detections_to_dense(scene.detections)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    scene_row["lift_s"] = time.perf_counter() - clock
    sizes = [(c.width_px, c.height_px) for c in scene.rig]
    result = calibrate_scene(dense, lifted, sizes, ExtrinsicsConfig(repair_views=_WORKER["repair"],
                                                                     scale_from_limbs=_WORKER["limbs"],
                                                                     **_WORKER["lens"]), scene_row)
    if result is None:
        return {"scene": scene_row, "views": []}
    fields, views = score_calibration(result, list(scene.rig), index, scene_row["far_views"])
    scene_row.update(fields)
    return {"scene": scene_row, "views": views}


def _run_and_store(job: tuple[int, int, str, int | None]) -> tuple[int, str]:
    index, seed, folder, views = job
    result = run_scene(index, seed, views)
    path = Path(folder) / f"scene_{index:04d}.json"
    partial = path.with_suffix(".partial")
    partial.write_text(json.dumps(result, default=float))
    os.replace(partial, path)
    row = result["scene"]
    return index, (f"scene {index:3d} {row['behaviour']:6s} {row['views']:2d} views {row['frames']:3d} frames "
                   f"{row['image']:9s} {row['cameras']:8s} lifter {row['lifter_seed']}: {row['outcome']}"
                   + (f", focal median {np.median([v['focal_error_pct'] for v in result['views']]):.2f} %"
                      if result["views"] else f" ({row.get('message', '')[:120]})")
                   + f" ({row.get('calibrate_s', 0):.1f} s)")


def summarise(scenes: pd.DataFrame, views: pd.DataFrame) -> dict:
    """Failures by kind, labels, and the error distributions by behaviour, lifter seed and scene factor."""
    out = {"scenes": int(len(scenes)), "views": int(len(views)),
           "outcomes": scenes["outcome"].value_counts().to_dict()}
    if "message" in scenes:
        failed = scenes[scenes["outcome"] != "ok"]
        out["failures"] = [{"scene": int(r.scene), "outcome": r.outcome, "behaviour": r.behaviour,
                            "views": int(r.views), "frames": int(r.frames), "message": r.message}
                           for r in failed.itertuples()]
    ok = scenes[scenes["outcome"] == "ok"]
    if len(ok):
        out["labels"] = {
            "world_frame_camera_0": int((ok["world_frame"] == "camera_0").sum()),
            "scenes_with_poorly_constrained_views": int((ok["poorly_constrained"] > 0).sum()),
            "scenes_with_failed_checks": int((ok["failed_checks"].fillna("") != "").sum()),
            "blocking_checks": pd.Series([c for f in ok["failed_checks"].fillna("") for c in f.split(",") if c])
            .value_counts().to_dict(),
            "up_source": ok["up_source"].value_counts().to_dict(),
        }
    if len(views):
        out["silent_failures"] = int(views["silent_failure"].sum())
        out["silent_failure_scenes"] = sorted(views.loc[views["silent_failure"], "scene"].unique().tolist())
        out["repaired_views"] = int(views["reregistered"].sum())
        out["views_disagreeing_first"] = int((views["first_agreement"] == "disagrees").sum())
        merged = views.merge(scenes, on="scene", suffixes=("", "_scene"))
        metrics = ("focal_error_pct", "angle_error_deg", "position_error_mm")
        out["all"] = {m: quantiles(merged[m]) for m in metrics}
        for factor in ("family", "behaviour", "lifter_seed", "cameras", "portrait", "distortion", "rig", "far"):
            out[f"by_{factor}"] = {str(key): {m: quantiles(group[m]) for m in metrics}
                                   for key, group in merged.groupby(factor)}
        # the acceptance's "people stand or walk" figures per lifter, and what the views left "ok" measure
        out["by_behaviour_lifter"] = {f"{behaviour} / {seed}": {m: quantiles(group[m]) for m in metrics}
                                      for (behaviour, seed), group in merged.groupby(["behaviour", "lifter_seed"])}
        unflagged = merged[merged["focal_status"] == "ok"]
        out["by_behaviour_unflagged"] = {str(key): {m: quantiles(group[m]) for m in metrics}
                                         for key, group in unflagged.groupby("behaviour")}
        bins = pd.cut(merged["views"], [1, 2, 8, 20, 31], labels=["2", "3-8", "9-20", "21-31"])
        out["by_views"] = {str(key): {m: quantiles(group[m]) for m in metrics}
                           for key, group in merged.groupby(bins, observed=True)}
        frames = pd.cut(merged["frames"], [0, 50, 120, 300], labels=["20-50", "51-120", "121-300"])
        out["by_frames"] = {str(key): {m: quantiles(group[m]) for m in metrics}
                            for key, group in merged.groupby(frames, observed=True)}
        out["up_error_deg"] = {str(key): quantiles(group["up_error_deg"]) for key, group in ok.groupby("behaviour")}
        many = ok[ok["views"] >= 21]
        out["calibrate_s"] = {"median": float(ok["calibrate_s"].median()), "max": float(ok["calibrate_s"].max()),
                              "views_21_31_median": float(many["calibrate_s"].median()) if len(many) else None,
                              "views_31": ok[ok["views"] == 31]["calibrate_s"].round(1).tolist()}
    return out


def _markdown(summary: dict) -> str:
    lines = [f"# Stress sweep: {summary['scenes']} scenes, {summary['views']} views", "",
             f"Outcomes: {summary['outcomes']}; silent failures (a view > {SILENT_FOCAL_PCT:g} % or > "
             f"{SILENT_ANGLE_DEG:g} deg off, every blocking check passed): {summary.get('silent_failures', 0)} views "
             f"in scenes {summary.get('silent_failure_scenes', [])}; views placed again: "
             f"{summary.get('repaired_views', 0)} (of {summary.get('views_disagreeing_first', 0)} that first "
             "disagreed)", ""]
    if summary.get("labels"):
        lines += [f"Labels: {summary['labels']}", ""]
    for factor in ("family", "behaviour", "lifter_seed", "behaviour_lifter", "behaviour_unflagged", "views", "frames",
                   "cameras", "portrait", "distortion", "rig", "far"):
        table = summary.get(f"by_{factor}")
        if not table:
            continue
        lines += [f"## by {factor}", "", "| " + factor + " | views | focal median % | focal p90 % | angle median deg "
                  "| angle p90 deg | position median mm |", "|---|---|---|---|---|---|---|"]
        for key, m in table.items():
            f, a, p = m["focal_error_pct"], m["angle_error_deg"], m["position_error_mm"]
            lines.append(f"| {key} | {f['n']} | {f['median']:.2f} | {f['p90']:.2f} | {a['median']:.2f} | "
                         f"{a['p90']:.2f} | {p['median']:.0f} |")
        lines.append("")
    for failure in summary.get("failures", []):
        lines.append(f"- scene {failure['scene']} ({failure['behaviour']}, {failure['views']} views, "
                     f"{failure['frames']} frames): {failure['outcome']}: {failure['message']}")
    return "\n".join(lines) + "\n"


def _plot(views: pd.DataFrame, scenes: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    merged = views.merge(scenes[["scene", "behaviour"]], on="scene")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for behaviour, group in merged.groupby("behaviour"):
        for ax, metric in zip(axes, ("focal_error_pct", "angle_error_deg")):
            values = np.sort(group[metric].to_numpy())
            ax.plot(np.maximum(values, 1e-3), np.arange(1, len(values) + 1) / len(values), label=f"{behaviour} "
                    f"({len(values)} views)")
    for ax, label in zip(axes, ("focal error (%)", "angle error (deg)")):
        ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("fraction of views")
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle("Camera initialisation, stress sweep: error distribution by behaviour")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = sweep_arguments(__doc__.splitlines()[0], scenes=102)
    parser.add_argument("--scale-from-lifted", action="store_true",
                        help="keep the world's scale the lifted people's sizes give (no rescaling to a reference adult)")
    parser.add_argument("--no-repair", action="store_true",
                        help="score the views' agreement but place no view again (the calibration before the repair)")
    parser.add_argument("--views", type=int, default=None,
                        help="every scene gets this many views instead of the drawn number (e.g. 31)")
    parser.add_argument("--max-k1-std", type=float, default=None,
                        help="the calibration's lens_max_k1_std (default: its own)")
    args = parser.parse_args()
    specs = [s.strip() for s in args.lifters.split(",") if s.strip()]
    for spec in specs:
        if spec != "shipped" and not Path(spec).is_file():
            parser.error(f"--lifters: {spec} is not a file (nor 'shipped')")
    folder = args.out / "scenes"
    folder.mkdir(parents=True, exist_ok=True)
    indices = [int(i) for i in args.only.split(",")] if args.only else list(range(args.scenes))
    todo = [i for i in indices if not (folder / f"scene_{i:04d}.json").exists()]
    print(f"{len(indices) - len(todo)} scenes already done in {folder}; {len(todo)} to run", flush=True)
    run_jobs([(i, args.seed, str(folder), args.views) for i in todo], _run_and_store, _init_worker,
             (specs, not args.no_repair, not args.scale_from_lifted,
              {} if args.max_k1_std is None else {"lens_max_k1_std": args.max_k1_std}), args.jobs)
    results = [json.loads((folder / f"scene_{i:04d}.json").read_text()) for i in indices]
    scenes = pd.DataFrame([r["scene"] for r in results])
    views = pd.DataFrame([v for r in results for v in r["views"]])
    summary = summarise(scenes, views)
    scenes.drop(columns=["traceback"], errors="ignore").to_csv(args.out / "scenes.csv", index=False)
    views.to_csv(args.out / "views.csv", index=False)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    (args.out / "summary.md").write_text(_markdown(summary))
    if len(views):
        _plot(views, scenes, args.out / "focal_error_cdf.png")
    print(_markdown(summary))
    for r in results:
        if r["scene"].get("traceback"):
            print(f"scene {r['scene']['scene']} crashed:\n{r['scene']['traceback']}")


if __name__ == "__main__":
    main()
