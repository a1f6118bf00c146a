"""The body fit on seeded synthetic scenes: the motion prior against the per-frame prior, no prior and the
triangulated skeletons, with the true cameras.

Each scene (``--scenes`` of them, drawn from ``--seed``: 2-5 people, 3-6 views, 150 frames, the demo preset's
behaviour otherwise) is generated, lifted with the shipped lifter, associated with the true cameras, and fitted
three ways with the default settings (``--methods`` picks fewer), the true cameras held fixed; every method is
scored by ``evaluation.body_metrics`` (the metric table's protocol). Prints one line per scene and method, then the
median and mean of every figure per method, and writes ``<out>/body_sweep.csv``.

A reference row, ``truth_smoothed_1f``, scores the ground truth itself smoothed in time by a Gaussian of one frame
(standard deviation): what a method that knew the truth but smoothed it as lightly as that would get. It feeds no
method; it says how much of the acceleration error any smooth motion pays for the truth's own fast changes.

    python scripts/body_sweep.py [--scenes 10] [--seed 0] [--jobs 2] [--out /tmp/body_sweep] [--set FIELD=VALUE]
                                 [--methods fit,fit_per_frame_prior,fit_no_prior]
"""

from __future__ import annotations

import argparse
import itertools
import os
from pathlib import Path

import numpy as np
import pandas as pd
from bench_fit import config_overrides
from sweep_summary import run_and_summarise

FIT_METHODS = ("fit", "fit_per_frame_prior", "fit_no_prior")
REFERENCE_SMOOTHING_FRAMES = 1.0
"""Standard deviation, in frames, of the Gaussian that smooths the truth for the reference row."""
_METRICS = ("mpjpe_mm", "pa_mpjpe_mm", "pcp_avg", "accel_error_mm_s2", "pve_mm", "reprojection_error_px", "seconds")


def scene_options(index: int, seed: int) -> dict:
    rng = np.random.default_rng([seed, index])
    return dict(seed=int(rng.integers(1_000_000)), num_people=int(rng.integers(2, 6)),
                num_views=int(rng.integers(3, 7)), num_frames=150)


def smoothed_truth(poses3d: pd.DataFrame, sigma_frames: float) -> pd.DataFrame:
    """The ``poses3d`` table with every person's joint tracks smoothed by a Gaussian of ``sigma_frames`` (frames)
    over each run of consecutive frames (edges: the nearest value repeated)."""
    from scipy.ndimage import gaussian_filter1d

    out = poses3d.sort_values(["person_id", "joint", "frame"]).copy()
    xyz = np.array(out[["x_m", "y_m", "z_m"]].to_numpy(float))  # a writable copy
    frames = out["frame"].to_numpy()
    track = (out["person_id"].astype(str) + "/" + out["joint"].astype(str)).to_numpy()
    run_start = np.r_[True, (track[1:] != track[:-1]) | (np.diff(frames) != 1)]
    bounds = np.r_[np.flatnonzero(run_start), len(out)]
    for a, b in itertools.pairwise(bounds):
        xyz[a:b] = gaussian_filter1d(xyz[a:b], sigma_frames, axis=0, mode="nearest")
    out[["x_m", "y_m", "z_m"]] = xyz
    return out


def run_scene(job: tuple[int, int, dict, tuple[str, ...]]) -> pd.DataFrame:
    import time

    import torch

    from evaluation.body_metrics import body_metric_rows, skeleton_accel_rows
    from humancal.association import associate, to_associations_table, to_skeletons_table
    from humancal.body import BodyModel
    from humancal.camera import CameraRig
    from humancal.datasets.sequences import SequenceSpec
    from humancal.fitting import BodyFitConfig, body_observations, fit_bodies
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
    from humancal.prior import shipped_prior
    from humancal.synthetic import generate_scene, preset
    from humancal.tables.detections import detections_to_dense

    torch.set_num_threads(1)
    index, seed, overrides, methods = job
    options = scene_options(index, seed)
    name = f"scene_{index:02d}"
    body = BodyModel()
    scene = generate_scene(preset("demo", **options), body, sequence=name)
    dense = detections_to_dense(scene.detections)
    rig = CameraRig.from_cameras(scene.rig)
    lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores, K=rig.K[dense.view])
    result = associate(dense, lifted, rig)
    people, skeletons = to_associations_table(result, name), to_skeletons_table(result, name)
    observations, _ = body_observations(dense, people, skeletons, len(rig))
    spec = SequenceSpec("synthetic", name, "synthetic", {})
    cameras = list(scene.rig)
    common = dict(associations=people, detections=scene.detections, cameras=cameras,
                  gt_associations=scene.associations, gt_poses3d=scene.poses3d, gt_cameras=cameras,
                  gt_motions=scene.motions, body=body, fps=scene.config.fps)
    rows = []
    priors = {"fit": lambda: shipped_prior()[0], "fit_per_frame_prior": lambda: shipped_prior("per_frame")[0],
              "fit_no_prior": lambda: None}
    for method in methods:
        prior = priors[method]()
        start = time.perf_counter()
        fit = fit_bodies(body, observations, rig, prior, BodyFitConfig(cameras="fixed").replace(**overrides), fps=scene.config.fps)
        seconds = time.perf_counter() - start
        for r in body_metric_rows(spec, motions=fit.motions.to_table(name), seconds=seconds, **common):
            rows.append({"scene": name, "method": method, "metric": r.metric, "value": r.value})
    for r in skeleton_accel_rows(spec, skeletons3d=skeletons, associations=people, fps=scene.config.fps,
                                 cameras=cameras, gt_associations=scene.associations, gt_poses3d=scene.poses3d,
                                 gt_cameras=cameras):
        rows.append({"scene": name, "method": "skeletons3d", "metric": r.metric, "value": r.value})
    reference = smoothed_truth(scene.poses3d, REFERENCE_SMOOTHING_FRAMES)
    for r in skeleton_accel_rows(spec, skeletons3d=reference, associations=scene.associations, fps=scene.config.fps,
                                 cameras=cameras, gt_associations=scene.associations, gt_poses3d=scene.poses3d,
                                 gt_cameras=cameras):
        rows.append({"scene": name, "method": "truth_smoothed_1f", "metric": r.metric, "value": r.value})
    table = pd.DataFrame(rows).assign(**{k: v for k, v in options.items()})
    wide = table[table["metric"].isin(_METRICS)].pivot_table(index="method", columns="metric", values="value")
    print(f"{name} {options}:\n{wide.round(2).to_string()}", flush=True)
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("/tmp/body_sweep"))
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a BodyFitConfig field of every fit (repeatable)")
    parser.add_argument("--methods", default=",".join(FIT_METHODS),
                        help=f"comma-separated fits to run, of {', '.join(FIT_METHODS)}")
    args = parser.parse_args()
    methods = tuple(m for m in args.methods.split(",") if m)
    unknown = sorted(set(methods) - set(FIT_METHODS))
    if unknown or not methods:
        parser.error(f"--methods: unknown {unknown}; choose from {', '.join(FIT_METHODS)}")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    jobs = [(i, args.seed, config_overrides(args.set), methods) for i in range(args.scenes)]
    wide = run_and_summarise(run_scene, jobs, args.jobs, _METRICS, args.out / "body_sweep.csv")
    if "fit" not in methods:
        return
    for metric in ("mpjpe_mm", "accel_error_mm_s2"):
        beats = {m: int((wide[("fit", metric)] < wide[(m, metric)]).sum())
                 for m in (*(m for m in methods if m != "fit"), "skeletons3d", "truth_smoothed_1f") if (m, metric) in wide}
        print(f"{metric}: the prior fit is lower than {beats} of {len(wide)} scenes")
    halved = wide[("skeletons3d", "accel_error_mm_s2")] / 2
    print(f"accel_error_mm_s2: half the skeletons' is reached by the fit in "
          f"{int((wide[('fit', 'accel_error_mm_s2')] <= halved).sum())} and by the reference row in "
          f"{int((wide[('truth_smoothed_1f', 'accel_error_mm_s2')] <= halved).sum())} of {len(wide)} scenes")


if __name__ == "__main__":
    main()
