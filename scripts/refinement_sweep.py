"""The joint refinement of cameras and motions on seeded synthetic scenes, against the camera initialisation and
the other regimes of the paper's Tables (``evaluation.method_comparison``).

Each scene is one of the camera-initialisation sweep's (``scripts/calibration_sweep.py``: 2-8 people, 3-8 views,
60-150 frames, focal lengths in 500-2500 px, a ring or an arc of cameras). It is lifted with the shipped lifter in
crop frames, calibrated (intrinsics, extrinsics) and associated with the estimated cameras exactly as the pipeline
does, then fitted by every ``--methods`` regime with the default fit settings. Prints one line per scene and
method, then the median and mean of every figure per method, and writes ``<out>/refinement_sweep.csv``.

    python scripts/refinement_sweep.py [--scenes 10] [--seed 7] [--jobs 2] [--methods init,int_ext,separate]
        [--set FIELD=VALUE ...] [--principal-point-offset PX] [--perturb S] [--keypoint-bias MM]
        [--out /tmp/refinement_sweep]

``--principal-point-offset`` moves every true camera's principal point that far from the image centre
(``SceneConfig.principal_point_offset_px``), where the calibration assumes it; the method ``int_ext_known_pp``
then shows what knowing it is worth.

``--perturb S`` moves every calibrated camera (after the association, before the fits; the ``init`` rows are the
moved cameras) by a seeded error of size S: focal length by up to S x 4 %, a rotation of S x 1 degree about a
random axis and the centre by S x 10 cm in a random direction. On the synthetic scenes the calibration is at the
noise floor, so the refinement has nothing to recover there; a perturbed start shows how far it brings cameras that
are off, as on real captures (Shelf's start is 77 mm off).

``--keypoint-bias MM`` gives the simulated detector its own definition of the joints
(``DetectorNoise.keypoint_bias_m``): each keypoint is seen away from the body model's by a per-scene offset fixed
in its bone, drawn with this std per axis, as a real detector trained on other annotations sees them.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from sweep_summary import run_and_summarise  # noqa: E402

_METRICS = ("focal_error_pct", "position_error_mm", "angle_error_deg", "reprojection_error_px", "mpjpe_mm",
            "pa_mpjpe_mm", "pcp_avg", "accel_error_mm_s2", "pve_mm", "seconds")


def _parse_value(text: str):
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def perturbed(cameras: list, size: float, rng: np.random.Generator) -> list:
    """The cameras with a seeded error of ``size`` (module docstring: x 4 % focal, 1 degree, 10 cm)."""
    from dataclasses import replace

    from humancal.geometry.rotations import axis_angle_to_rotmat

    out = []
    for camera in cameras:
        K = camera.K.copy()
        K[[0, 1], [0, 1]] *= 1.0 + size * rng.uniform(-0.04, 0.04)
        axis = rng.normal(size=3)
        turn = axis_angle_to_rotmat(axis / np.linalg.norm(axis), np.radians(size))
        R = turn @ camera.R_cam_from_world
        offset = rng.normal(size=3)
        centre = camera.center_world_m + size * 0.1 * offset / np.linalg.norm(offset)
        out.append(replace(camera, K=K, R_cam_from_world=R, t_cam_from_world_m=-R @ centre))
    return out


def run_scene(job: tuple[int, int, tuple[str, ...], dict]) -> pd.DataFrame:
    import torch
    from calibration_sweep import calibrate, lift_with, scene_config

    from evaluation.camera_metrics import camera_metrics
    from evaluation.method_comparison import method_metric_table
    from evaluation.protocols import metrics_table
    from humancal.association import associate, to_associations_table, to_skeletons_table
    from humancal.body import BodyModel
    from humancal.calibration import CalibrationError, IntrinsicsConfig
    from humancal.camera import CameraRig
    from humancal.datasets.sequences import SequenceSpec
    from humancal.fitting import BodyFitConfig
    from humancal.lifter import load_lifter, shipped_checkpoint
    from humancal.prior import shipped_prior
    from humancal.prior.weights import PriorWeightsError
    from humancal.synthetic import generate_scene

    torch.set_num_threads(1)
    from dataclasses import replace

    index, seed, methods, overrides, pp_offset_px, perturb, bias_mm = job
    config = scene_config(index, seed)
    config = config.replace(principal_point_offset_px=pp_offset_px,
                            noise=replace(config.noise, keypoint_bias_m=bias_mm / 1000.0))
    name = f"scene_{index:02d}"
    body = BodyModel()
    scene = generate_scene(config, body, sequence=name)
    dense, lifted, _ = lift_with(load_lifter(shipped_checkpoint()), scene.detections)
    sizes = [(c.width_px, c.height_px) for c in scene.rig]
    try:
        _, extrinsics, _ = calibrate(dense, lifted, sizes, IntrinsicsConfig(missing_upright="defer"))
    except CalibrationError as error:
        print(f"{name}: calibration failed: {error}", flush=True)
        return pd.DataFrame()
    cameras = extrinsics.cameras
    result = associate(dense, lifted, CameraRig.from_cameras(cameras))
    people, skeletons = to_associations_table(result, name), to_skeletons_table(result, name)
    if perturb > 0:
        cameras = perturbed(cameras, perturb, np.random.default_rng([seed, index, 1]))
    spec = SequenceSpec("synthetic", name, "synthetic", {})
    variants = {}

    def priors(variant: str):
        if variant not in variants:
            try:
                variants[variant] = shipped_prior(variant)[0]
            except PriorWeightsError:
                variants[variant] = None
        return variants[variant]

    gt = list(scene.rig)
    init_rows = metrics_table("synthetic", name, "init", camera_metrics(cameras, gt, scene.detections,
                                                                        scene.associations))
    table = method_metric_table(
        spec, methods=list(methods), priors=priors, body=body, config=BodyFitConfig().replace(**overrides),
        fps=scene.config.fps, dense=dense, lifted=lifted, detections=scene.detections, associations=people,
        skeletons3d=skeletons, cameras=cameras, gt_associations=scene.associations, gt_poses3d=scene.poses3d,
        gt_cameras=gt, gt_motions=scene.motions)
    table = pd.concat([init_rows, table], ignore_index=True)
    table = table[table["view"].isna()].assign(scene=name, people=config.num_people, views=config.num_views,
                                               frames=config.num_frames)
    wide = table[table["metric"].isin(_METRICS)].pivot_table(index="method", columns="metric", values="value",
                                                             aggfunc="first")
    print(f"{name} ({config.num_people} people, {config.num_views} views, {config.num_frames} frames):\n"
          f"{wide.round(2).to_string()}", flush=True)
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--methods", default="init,int_ext,separate")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="a BodyFitConfig field for every method (repeatable)")
    parser.add_argument("--principal-point-offset", type=float, default=0.0, metavar="PX",
                        help="move the true principal points this far from the image centres (default 0)")
    parser.add_argument("--perturb", type=float, default=0.0, metavar="S",
                        help="move the calibrated cameras by a seeded error of this size before the fits (default 0)")
    parser.add_argument("--keypoint-bias", type=float, default=0.0, metavar="MM",
                        help="the detector's systematic keypoint offsets, std per axis in mm (default 0)")
    parser.add_argument("--out", type=Path, default=Path("/tmp/refinement_sweep"))
    args = parser.parse_args()
    overrides = dict((k, _parse_value(v)) for k, v in (s.split("=", 1) for s in args.set))
    methods = tuple(args.methods.split(","))
    jobs = [(i, args.seed, methods, overrides, args.principal_point_offset, args.perturb,
             args.keypoint_bias) for i in range(args.scenes)]
    wide = run_and_summarise(run_scene, jobs, args.jobs, _METRICS, args.out / "refinement_sweep.csv")
    if "int_ext" in methods:
        for metric in ("focal_error_pct", "position_error_mm", "angle_error_deg", "reprojection_error_px"):
            if ("init", metric) in wide and ("int_ext", metric) in wide:
                better = int((wide[("int_ext", metric)] < wide[("init", metric)]).sum())
                print(f"{metric}: int_ext below init in {better} of {len(wide)} scenes")


if __name__ == "__main__":
    main()
