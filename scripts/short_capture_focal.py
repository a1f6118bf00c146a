"""How well a short capture fixes the focal lengths: the ``tiny`` preset (2 people, 3 views, 20 frames) drawn with
several seeds, calibrated with variants of ``ExtrinsicsConfig``, and what the reprojection alone says about them.

Part 1 (always): every scene (``--seeds`` of the ``tiny`` preset, plus the demo scene) is lifted with the shipped
lifter in crop frames and calibrated (``estimate_intrinsics`` with ``missing_upright="defer"``, then
``estimate_extrinsics``) once per ``--variant``; prints each view's focal error against the truth and its status.

Part 2 (``--valley``): on the first seed's scene, a bundle adjustment of the reprojection alone (the body fit's,
``humancal.fitting.bundle.bundle_adjust``: free points, a negligible camera tie), started at the true cameras and
at the calibration's, by L-BFGS for 100 / 1,000 / 3,000 iterations and by Levenberg-Marquardt to convergence; then one view's focal scaled by 0.85-1.15
with the other cameras true and the extrinsics and points refitted. The truth is used here to ask what the data
can determine (evaluation only; no method reads it).

    python scripts/short_capture_focal.py [--seeds 1,0,2,3] [--variant FIELD=VALUE[;FIELD=VALUE...]]... [--valley]

Example (the table of ``docs/calibration.md``)::

    python scripts/short_capture_focal.py --variant "" --variant bundle_iterations=200 --variant shape_std_m=2 \
        --variant shape_std_m=0.2 --variant person_scale_std=None \
        --variant "shape_std_m=1000;person_scale_std=None;bundle_iterations=400" --valley

Part 2 starts its second bundle adjustment from the first variant's cameras (give the defaults first).
"""

from __future__ import annotations

import argparse
import dataclasses
import os

import numpy as np

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def parse_variant(text: str) -> dict:
    """``"a=1;b=None"`` -> ``{"a": 1.0, "b": None}`` (integers stay integers)."""
    out = {}
    for item in filter(None, text.split(";")):
        field, _, value = item.partition("=")
        if not value:
            raise SystemExit(f"--variant: expected FIELD=VALUE, got {item!r}")
        out[field.strip()] = None if value == "None" else int(value) if value.lstrip("-").isdigit() else float(value)
    return out


def calibrate(scene, lifter, overrides: dict):
    from humancal.calibration import IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
    from humancal.calibration.extrinsics_config import ExtrinsicsConfig
    from humancal.detections import detections_to_dense
    from humancal.lifter import lift_detections

    dense = detections_to_dense(scene.detections)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    sizes = [(c.width_px, c.height_px) for c in scene.rig]
    intrinsics = estimate_intrinsics(dense, lifted, sizes, IntrinsicsConfig(missing_upright="defer"))
    return estimate_extrinsics(dense, lifted, intrinsics, ExtrinsicsConfig(**overrides))


def focal_errors_pct(cameras, truth) -> np.ndarray:
    return np.array([100.0 * (c.K[0, 0] / t.K[0, 0] - 1.0) for c, t in zip(cameras, truth, strict=True)])


def valley(scene, start_cameras) -> None:
    import torch

    from humancal.association import associate, to_associations_table, to_skeletons_table
    from humancal.camera import CameraRig
    from humancal.detections import detections_to_dense
    from humancal.fitting import BodyFitConfig, body_observations
    from humancal.fitting.bundle import bundle_adjust
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint

    torch.set_num_threads(2)
    truth = list(scene.rig)
    dense = detections_to_dense(scene.detections)
    config = BodyFitConfig(weight_camera_prior=1e-8)

    def observations(rig):
        lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores,
                                 K=rig.K[dense.view])
        result = associate(dense, lifted, rig)
        return body_observations(dense, to_associations_table(result, "s"), to_skeletons_table(result, "s"),
                                 len(rig))[0]

    for label, cameras in (("the true cameras", truth), ("the calibration's cameras", start_cameras)):
        rig = CameraRig.from_cameras(cameras)
        obs = observations(rig)
        for solver, iterations in (("lbfgs", 100), ("lbfgs", 1000), ("lbfgs", 3000), ("lm", 100)):
            result = bundle_adjust(obs, rig, config.replace(bundle_solver=solver), regime="int_ext",
                                   iterations=iterations)
            errors = focal_errors_pct(result.cameras.to_cameras(), truth)
            print(f"reprojection-only bundle from {label}, {solver} {iterations} iterations: focal % "
                  f"{np.round(errors, 2)} (mean |.| {np.abs(errors).mean():.2f}), mean reprojection "
                  f"{result.reprojection_error_px:.3f} px")
    obs = observations(CameraRig.from_cameras(truth))
    for scale in (0.85, 0.92, 1.0, 1.08, 1.15):
        cameras = list(truth)
        K = cameras[1].K.copy()
        K[:2, :2] *= scale
        cameras[1] = dataclasses.replace(cameras[1], K=K)
        result = bundle_adjust(obs, CameraRig.from_cameras(cameras), config, regime="ext", iterations=1000)
        print(f"view 1 focal x {scale:.2f}, the others true, extrinsics and points refitted: mean reprojection "
              f"{result.reprojection_error_px:.3f} px")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1,0,2,3", help="seeds of the tiny preset (the graph's synthetic__tiny: 1)")
    parser.add_argument("--variant", action="append", default=None, metavar="FIELD=VALUE[;...]",
                        help="ExtrinsicsConfig overrides, repeatable; an empty string is the defaults")
    parser.add_argument("--valley", action="store_true", help="part 2 on the first seed's scene")
    args = parser.parse_args()
    variants = [parse_variant(v) for v in (args.variant or [""])]

    from humancal.body import BodyModel
    from humancal.lifter import load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset

    body, lifter = BodyModel(), load_lifter(shipped_checkpoint())
    seeds = [int(s) for s in args.seeds.split(",") if s]
    scenes = [(f"tiny seed {s}", generate_scene(preset("tiny", seed=s), body)) for s in seeds]
    scenes.append(("demo", generate_scene(preset("demo"), body)))
    first_calibration = None
    for overrides in variants:
        print(f"ExtrinsicsConfig({', '.join(f'{k}={v}' for k, v in overrides.items())}):")
        for name, scene in scenes:
            result = calibrate(scene, lifter, overrides)
            errors = focal_errors_pct(result.cameras, list(scene.rig))
            status = list(result.diagnostics.per_view["focal_status"])
            print(f"  {name:12s} focal % {np.round(errors, 2)}  mean |.| {np.abs(errors).mean():5.2f}  max "
                  f"{np.abs(errors).max():5.2f}  {status}", flush=True)
            if first_calibration is None:
                first_calibration = result.cameras
    if args.valley:
        valley(scenes[0][1], first_calibration)


if __name__ == "__main__":
    main()
