"""How well a short capture fixes the focal lengths: the ``tiny`` preset (2 people, 3 views, 20 frames) drawn with
several seeds, calibrated with variants of ``ExtrinsicsConfig``, and what the reprojection alone says about them.

Part 1 (always): every scene (``--seeds`` of the ``tiny`` preset, plus the demo scene) is lifted with the shipped
lifter in crop frames and calibrated (``estimate_intrinsics`` with ``missing_upright="defer"``, then
``estimate_extrinsics``) once per ``--variant``; prints each view's focal error against the truth and its status.

Part 2 (``--valley``): on the first seed's scene, a bundle adjustment of the reprojection alone (the body fit's,
``humancal.fitting.joint_bundle.bundle_adjust_on_joints``: free points, a negligible camera tie), started at the true
cameras and at the calibration's, by L-BFGS for 100 / 1,000 / 3,000 iterations and by Levenberg-Marquardt to
convergence; then one view's focal scaled by 0.85-1.15
with the other cameras true and the extrinsics and points refitted. The truth is used here to ask what the data
can determine (evaluation only; no method reads it).

    python scripts/short_capture_focal.py [--seeds 1,0,2,3] [--variant FIELD=VALUE[;FIELD=VALUE...]]... [--valley]
        [--lifter PATH] [--no-demo]

With more than one seed, each variant ends with the distribution over the draws (median and 90th percentile of
the per-draw mean focal error, and how many draws are within 2 % on average and in every view).

Example (the table of ``docs/calibration.md``)::

    python scripts/short_capture_focal.py --variant "" --variant bundle_iterations=200 --variant shape_std_m=2 \
        --variant shape_std_m=0.2 --variant person_scale_std=None \
        --variant "shape_std_m=1000;person_scale_std=None;bundle_iterations=400" --valley

Part 2 starts its second bundle adjustment from the first variant's cameras (give the defaults first).

``--data-minimum`` adds, for every ``tiny`` draw of the first variant, the focal error at the reprojection-only
minimum that Levenberg-Marquardt reaches from the calibration's cameras (the detections associated by those cameras,
and by the true ones): what the detections themselves say about the focal lengths, against which the calibration's
answer is judged (evaluation only).
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
    from humancal.lifter import lift_detections
    from humancal.tables.detections import detections_to_dense

    dense = detections_to_dense(scene.detections)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    sizes = [(c.width_px, c.height_px) for c in scene.rig]
    intrinsics = estimate_intrinsics(dense, lifted, sizes, IntrinsicsConfig(missing_upright="defer"))
    return estimate_extrinsics(dense, lifted, intrinsics, ExtrinsicsConfig(**overrides))


def focal_errors_pct(cameras, truth) -> np.ndarray:
    return np.array([100.0 * (c.K[0, 0] / t.K[0, 0] - 1.0) for c, t in zip(cameras, truth, strict=True)])


def _observations(scene, rig, lifter):
    """The body fit's observations of the scene's detections, associated with ``rig``'s cameras."""
    from humancal.association import associate, to_associations_table, to_skeletons_table
    from humancal.fitting import body_observations
    from humancal.lifter import lift_detections
    from humancal.tables.detections import detections_to_dense

    dense = detections_to_dense(scene.detections)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores, K=rig.K[dense.view])
    result = associate(dense, lifted, rig)
    return body_observations(dense, to_associations_table(result, "s"), to_skeletons_table(result, "s"), len(rig))[0]


def _reprojection_bundle(obs, start_rig, solver: str = "lm", iterations: int = 100):
    """Bundle adjustment of the reprojection alone (free points, a negligible camera tie), focal + extrinsics."""
    from humancal.fitting import BodyFitConfig
    from humancal.fitting.joint_bundle import bundle_adjust_on_joints

    config = BodyFitConfig(weight_camera_prior=1e-8, bundle_solver=solver)
    return bundle_adjust_on_joints(obs, start_rig, config, regime="int_ext", iterations=iterations)


def data_minimum(scene, lifter, calibrated) -> tuple[float, float]:
    """Mean |focal error| % of the reprojection-only minimum reached by Levenberg-Marquardt from the calibration's
    cameras, with the detections associated by the calibration's cameras and by the true ones (evaluation only:
    what the detections themselves say about the focal lengths)."""
    from humancal.camera import CameraRig

    truth = list(scene.rig)
    start = CameraRig.from_cameras(calibrated)
    out = []
    for cameras in (calibrated, truth):
        result = _reprojection_bundle(_observations(scene, CameraRig.from_cameras(cameras), lifter), start)
        out.append(float(np.abs(focal_errors_pct(result.cameras.to_cameras(), truth)).mean()))
    return out[0], out[1]


def valley(scene, start_cameras, lifter) -> None:
    import torch

    from humancal.camera import CameraRig
    from humancal.fitting import BodyFitConfig
    from humancal.fitting.joint_bundle import bundle_adjust_on_joints

    torch.set_num_threads(2)
    truth = list(scene.rig)
    config = BodyFitConfig(weight_camera_prior=1e-8)
    for label, cameras in (("the true cameras", truth), ("the calibration's cameras", start_cameras)):
        rig = CameraRig.from_cameras(cameras)
        obs = _observations(scene, rig, lifter)
        for solver, iterations in (("lbfgs", 100), ("lbfgs", 1000), ("lbfgs", 3000), ("lm", 100)):
            result = _reprojection_bundle(obs, rig, solver, iterations)
            errors = focal_errors_pct(result.cameras.to_cameras(), truth)
            print(f"reprojection-only bundle from {label}, {solver} {iterations} iterations: focal % "
                  f"{np.round(errors, 2)} (mean |.| {np.abs(errors).mean():.2f}), mean reprojection "
                  f"{result.reprojection_error_px:.3f} px")
    obs = _observations(scene, CameraRig.from_cameras(truth), lifter)
    for scale in (0.85, 0.92, 1.0, 1.08, 1.15):
        cameras = list(truth)
        K = cameras[1].K.copy()
        K[:2, :2] *= scale
        cameras[1] = dataclasses.replace(cameras[1], K=K)
        result = bundle_adjust_on_joints(obs, CameraRig.from_cameras(cameras), config, regime="ext", iterations=1000)
        print(f"view 1 focal x {scale:.2f}, the others true, extrinsics and points refitted: mean reprojection "
              f"{result.reprojection_error_px:.3f} px")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1,0,2,3", help="seeds of the tiny preset (the graph's synthetic__tiny: 1)")
    parser.add_argument("--variant", action="append", default=None, metavar="FIELD=VALUE[;...]",
                        help="ExtrinsicsConfig overrides, repeatable; an empty string is the defaults")
    parser.add_argument("--valley", action="store_true", help="part 2 on the first seed's scene")
    parser.add_argument("--lifter", default="shipped",
                        help="lifter checkpoint for part 1 (a file written by scripts/train_lifter.py, or 'shipped')")
    parser.add_argument("--data-minimum", action="store_true",
                        help="for each tiny draw of the first variant, the reprojection-only minimum's focal error")
    parser.add_argument("--no-demo", action="store_true", help="leave the demo scene out of part 1")
    args = parser.parse_args()
    variants = [parse_variant(v) for v in (args.variant or [""])]

    from humancal.body import BodyModel
    from humancal.lifter import load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset

    body, lifter = BodyModel(), load_lifter(shipped_checkpoint() if args.lifter == "shipped" else args.lifter)
    seeds = [int(s) for s in args.seeds.split(",") if s]
    scenes = [(f"tiny seed {s}", generate_scene(preset("tiny", seed=s), body)) for s in seeds]
    if not args.no_demo:
        scenes.append(("demo", generate_scene(preset("demo"), body)))
    first_calibration = None
    for index, overrides in enumerate(variants):
        print(f"ExtrinsicsConfig({', '.join(f'{k}={v}' for k, v in overrides.items())}):")
        draws = []  # (mean, max) |focal error| % of each tiny draw
        for name, scene in scenes:
            result = calibrate(scene, lifter, overrides)
            errors = focal_errors_pct(result.cameras, list(scene.rig))
            if name.startswith("tiny"):
                draws.append((np.abs(errors).mean(), np.abs(errors).max()))
            status = list(result.diagnostics.per_view["focal_status"])
            minimum = ""
            if args.data_minimum and name.startswith("tiny") and index == 0:
                by_calibration, by_truth = data_minimum(scene, lifter, result.cameras)
                minimum = f"  reprojection minimum: mean |.| {by_calibration:.2f} (associated by the truth: {by_truth:.2f})"
            print(f"  {name:12s} focal % {np.round(errors, 2)}  mean |.| {np.abs(errors).mean():5.2f}  max "
                  f"{np.abs(errors).max():5.2f}  {status}{minimum}", flush=True)
            if first_calibration is None:
                first_calibration = result.cameras
        if len(draws) > 1:
            mean, worst = np.array(draws).T
            print(f"  {len(draws)} tiny draws: mean focal error median {np.median(mean):.2f} %, 90th percentile "
                  f"{np.percentile(mean, 90):.2f} %; within 2 % on average {int((mean <= 2).sum())}, in every view "
                  f"{int((worst <= 2).sum())}", flush=True)
    if args.valley:
        valley(scenes[0][1], first_calibration, lifter)


if __name__ == "__main__":
    main()
