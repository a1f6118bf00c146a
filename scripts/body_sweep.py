"""The body fit on seeded synthetic scenes: the motion prior against the per-frame prior, no prior and the
triangulated skeletons, with the true cameras.

Each scene (``--scenes`` of them, drawn from ``--seed``: 2-5 people, 3-6 views, 150 frames, the demo preset's
behaviour otherwise) is generated, lifted with the shipped lifter, associated with the true cameras, and fitted
three ways with the default settings, the true cameras held fixed; every method is scored by
``evaluation.body_metrics`` (the metric table's protocol). Prints one line per scene and method, then the median and mean of every figure per method, and writes
``<out>/body_sweep.csv``.

    python scripts/body_sweep.py [--scenes 10] [--seed 0] [--jobs 2] [--out /tmp/body_sweep] [--set FIELD=VALUE]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import pandas as pd
from bench_fit import config_overrides
from sweep_summary import run_and_summarise

_METRICS = ("mpjpe_mm", "pa_mpjpe_mm", "pcp_avg", "accel_error_mm_s2", "pve_mm", "reprojection_error_px", "seconds")


def scene_options(index: int, seed: int) -> dict:
    rng = np.random.default_rng([seed, index])
    return dict(seed=int(rng.integers(1_000_000)), num_people=int(rng.integers(2, 6)),
                num_views=int(rng.integers(3, 7)), num_frames=150)


def run_scene(job: tuple[int, int, dict]) -> pd.DataFrame:
    import time

    import torch

    from evaluation.body_metrics import body_metric_rows, skeleton_accel_rows
    from humancal.association import associate, to_associations_table, to_skeletons_table
    from humancal.body import BodyModel
    from humancal.camera import CameraRig
    from humancal.detections import detections_to_dense
    from humancal.fitting import BodyFitConfig, body_observations, fit_bodies
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
    from humancal.prior import shipped_prior
    from humancal.sequences import SequenceSpec
    from humancal.synthetic import generate_scene, preset

    torch.set_num_threads(1)
    index, seed, overrides = job
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
    for method, prior in (("fit", shipped_prior()[0]), ("fit_per_frame_prior", shipped_prior("per_frame")[0]),
                          ("fit_no_prior", None)):
        start = time.perf_counter()
        fit = fit_bodies(body, observations, rig, prior, BodyFitConfig(cameras="fixed").replace(**overrides), fps=scene.config.fps)
        seconds = time.perf_counter() - start
        for r in body_metric_rows(spec, motions=fit.motions.to_table(name), seconds=seconds, **common):
            rows.append({"scene": name, "method": method, "metric": r.metric, "value": r.value})
    for r in skeleton_accel_rows(spec, skeletons3d=skeletons, associations=people, fps=scene.config.fps,
                                 cameras=cameras, gt_associations=scene.associations, gt_poses3d=scene.poses3d,
                                 gt_cameras=cameras):
        rows.append({"scene": name, "method": "skeletons3d", "metric": r.metric, "value": r.value})
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
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    jobs = [(i, args.seed, config_overrides(args.set)) for i in range(args.scenes)]
    wide = run_and_summarise(run_scene, jobs, args.jobs, _METRICS, args.out / "body_sweep.csv")
    for metric in ("mpjpe_mm", "accel_error_mm_s2"):
        beats = {m: int((wide[("fit", metric)] < wide[(m, metric)]).sum())
                 for m in ("fit_per_frame_prior", "fit_no_prior", "skeletons3d")}
        print(f"{metric}: the prior fit is lower than {beats} of {len(wide)} scenes")


if __name__ == "__main__":
    main()
