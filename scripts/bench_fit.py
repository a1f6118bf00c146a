"""Run time, memory and accuracy of the body fit on the benchmark workload: 900 frames, 5 views, 4 people.

Builds the synthetic ``benchmark`` scene, lifts its detections with the shipped lifter and associates them with the
true cameras (none of that is timed), then fits every person's shape and motion with the shipped motion prior
(:func:`humancal.fitting.fit_bodies`, default settings; the true cameras held fixed unless ``--cameras`` says
which of their parameters move from there) and prints the seconds of each stage, the peak memory of the
process, and the fit's MPJPE and acceleration error against the ground truth beside the triangulated skeletons'.

    python scripts/bench_fit.py [--preset benchmark] [--threads 2] [--prior motion_prior|per_frame|none]
                                [--cameras fixed|ext|int_ext]
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np
import threadpoolctl
import torch

from humancal.association import associate, to_associations_table, to_skeletons_table
from humancal.body import BodyModel
from humancal.camera import CameraRig
from humancal.fitting import BodyFitConfig, body_observations, fit_bodies
from humancal.keypoints import JOINT_INDEX
from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
from humancal.prior import shipped_prior
from humancal.synthetic import generate_scene, preset
from humancal.tables.associations import Associations
from humancal.tables.detections import detections_to_dense


def _peak_rss_mb() -> float:
    """The process's peak resident memory since it started or since :func:`_reset_peak`, MB (Linux)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _reset_peak() -> bool:
    """Reset the peak resident memory (Linux ``clear_refs``), so the fit's own peak can be read; False if not."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def _errors(scene, motions, skeletons, truth_of):
    """(fit MPJPE mm, skeleton MPJPE mm, fit accel mm/s^2, skeleton accel mm/s^2) over present frames."""
    fps = scene.config.fps
    acc = lambda x: x[2:] - 2 * x[1:-1] + x[:-2]  # noqa: E731
    out = np.zeros(4)
    for p, pid in enumerate(motions.person_ids):
        gt = scene.keypoints_world_m[truth_of[int(pid)]][motions.frames]
        rows = skeletons[skeletons["person_id"] == pid]
        tri = np.full(gt.shape, np.nan)
        tri[rows["frame"].to_numpy() - motions.frames[0], rows["joint"].map(JOINT_INDEX).to_numpy()] = \
            rows[["x_m", "y_m", "z_m"]].to_numpy()
        keep = motions.present[p]
        fit = motions.keypoints_world_m[p]
        out += [np.linalg.norm(fit - gt, axis=-1)[keep].mean(), np.nanmean(np.linalg.norm(tri - gt, axis=-1)[keep]),
                np.linalg.norm(acc(fit) - acc(gt), axis=-1).mean() * fps**2,
                np.nanmean(np.linalg.norm(acc(tri) - acc(gt), axis=-1)) * fps**2]
    return 1000.0 * out / motions.num_people


def config_overrides(items: list[str]) -> dict:
    """``["FIELD=VALUE", ...]`` -> BodyFitConfig field changes, each value of its field's type."""
    overrides = {}
    for item in items:
        name, _, value = item.partition("=")
        kind = type(getattr(BodyFitConfig(), name))
        overrides[name] = value if kind is str else kind(float(value) if "." in value else int(value))
    return overrides


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="benchmark")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--prior", default="motion_prior", choices=["motion_prior", "per_frame", "none"])
    parser.add_argument("--cameras", default="fixed", choices=["fixed", "ext", "int_ext"],
                        help="which camera parameters the fit refines (fixed: the fitted-motions regime)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a BodyFitConfig field (repeatable), e.g. --set iterations_3d=200")
    args = parser.parse_args()
    overrides = config_overrides(args.set)
    config = BodyFitConfig().replace(cameras=args.cameras, **overrides)
    torch.set_num_threads(args.threads)
    with threadpoolctl.threadpool_limits(args.threads):
        body = BodyModel()
        scene = generate_scene(preset(args.preset), body, sequence=args.preset)
        dense = detections_to_dense(scene.detections)
        rig = CameraRig.from_cameras(scene.rig)
        lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores,
                                 K=rig.K[dense.view])
        result = associate(dense, lifted, rig)
        people = to_associations_table(result, args.preset)
        skeletons = to_skeletons_table(result, args.preset)
        observations, warnings = body_observations(dense, people, skeletons, len(rig))
        prior = None if args.prior == "none" else shipped_prior(args.prior)[0]
        print(f"workload: {observations.num_frames} frames, {len(rig)} views, {observations.num_people} people "
              f"({observations.present.sum()} person-frames), prior {args.prior}, cameras {args.cameras}, "
              f"{args.threads} thread(s), "
              f"settings changed {overrides or 'none'}; "
              f"peak memory before the fit {_peak_rss_mb():.0f} MB")
        reset = _reset_peak()
        start = time.perf_counter()
        fit = fit_bodies(body, observations, rig, prior, config, fps=scene.config.fps)
        wall = time.perf_counter() - start
    stages = ", ".join(f"{k} {v:.2f}" for k, v in fit.stage_seconds.items())
    scope = "during the fit" if reset else "of the whole process"
    print(f"fit seconds: {stages} (wall {wall:.2f}); peak memory {scope} {_peak_rss_mb():.0f} MB")
    truth = Associations.from_table(scene.associations).person_of_detections(dense)
    found = Associations.from_table(people).person_of_detections(dense)
    truth_of = {int(pid): int(np.bincount(truth[(found == pid) & (truth >= 0)]).argmax())
                for pid in fit.motions.person_ids}
    mpjpe, skel_mpjpe, accel, skel_accel = _errors(scene, fit.motions, skeletons, truth_of)
    print(f"MPJPE fit {mpjpe:.1f} mm (skeletons3d {skel_mpjpe:.1f}); acceleration error fit {accel:.0f} mm/s^2 "
          f"(skeletons3d {skel_accel:.0f}); reprojection {fit.reprojection_error_px:.2f} px")


if __name__ == "__main__":
    main()
