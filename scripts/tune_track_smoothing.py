"""How the temporal refinement of the tracked skeletons (``SmoothingConfig``) changes their accuracy on synthetic
scenes: the data its defaults were chosen on (never Shelf, which is the test set).

For each scene (the generator's detector noise: missed joints, jitter, false positives, left-right flips) the
association runs with the true cameras and with the cameras humancal estimates from the scene (the skeletons then mapped
into the true world by the similarity of the camera centres, as the evaluation protocol does), once per setting of a grid of
``scale_px`` x ``acceleration_mps2``, and once without the refinement. Prints, per setting, the MPJPE (mm) of the
skeletons against the true joints, the PCP (%) of the 12 body limbs (a joint missing counts as wrong) and the share
of true joints predicted, averaged over the scenes.

    python scripts/tune_track_smoothing.py [--scenes arc,demo,crowd] [--frames 150] [--iterations 1,2,3]
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from evaluation.metrics import pcp_correct
from humancal.association import TrackingConfig, associate
from humancal.association.track_smoothing import SmoothingConfig
from humancal.body import BodyModel
from humancal.calibration import IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
from humancal.calibration.rig_alignment import align_rig
from humancal.camera import CameraRig
from humancal.keypoints import LIMB_INDEX
from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
from humancal.synthetic import generate_scene, preset
from humancal.tables.associations import Associations
from humancal.tables.detections import detections_to_dense


def self_calibrated(scene, dense, lifted) -> tuple[list, object]:
    """The scene's cameras as humancal estimates them, and the similarity that maps their world onto the true one
    (fitted on the camera centres, as the evaluation protocol does)."""
    intrinsics = estimate_intrinsics(dense, lifted, [(c.width_px, c.height_px) for c in scene.rig],
                                     IntrinsicsConfig(missing_upright="defer"))
    cameras = estimate_extrinsics(dense, lifted, intrinsics).cameras
    return cameras, align_rig(cameras, list(scene.rig))


def scores(scene, dense, truth, result, to_true_world) -> tuple[float, float, float]:
    """(MPJPE mm, limb PCP %, coverage %) of the result's skeletons, mapped by ``to_true_world``, against the
    scene's true joints."""
    ids = np.asarray(scene.person_ids)
    true_of = {}
    for p in np.unique(result.person_id[result.person_id >= 0]):
        t = truth[(result.person_id == p) & (truth >= 0)]
        if len(t):
            true_of[int(p)] = int(np.bincount(t).argmax())
    # one predicted skeleton per true person and frame (the first one mapped to it)
    pred = np.full(scene.keypoints_world_m.shape, np.nan)
    for f, p, X in zip(result.skeleton_frame, result.skeleton_person, result.joints_world_m):
        t = true_of.get(int(p))
        if t is not None:
            k = int(np.flatnonzero(ids == t)[0])
            if np.isnan(pred[k, f]).all():
                pred[k, f] = X if to_true_world is None else to_true_world.apply(X)
    gt = scene.keypoints_world_m
    seen = np.zeros(gt.shape[:2], bool)  # true person-frames that some view detected
    seen[np.searchsorted(ids, truth[truth >= 0]), dense.frame[truth >= 0]] = True
    g, x = gt[seen], pred[seen]
    err = np.linalg.norm(x - g, axis=-1)
    ok = np.isfinite(err)
    correct = pcp_correct(x, g, list(LIMB_INDEX[:12]))
    return float(err[ok].mean() * 1000), float(100 * correct.mean()), float(100 * ok.mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="arc,demo,crowd")
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--scale-px", default="3,6,12")
    parser.add_argument("--acceleration", default="10,30,90")
    parser.add_argument("--iterations", default="2", help="reweighting iterations (comma-separated to compare)")
    args = parser.parse_args()
    body = BodyModel()
    lifter = load_lifter(shipped_checkpoint())
    settings = [SmoothingConfig(enabled=False)] + [
        SmoothingConfig(scale_px=float(s), acceleration_mps2=float(a), iterations=int(i))
        for s, a, i in itertools.product(args.scale_px.split(","), args.acceleration.split(","),
                                         args.iterations.split(","))]
    table = {}
    for index, name in enumerate(args.scenes.split(",")):
        scene = generate_scene(preset(name, num_frames=args.frames, seed=100 + index), body, sequence=name)
        dense = detections_to_dense(scene.detections)
        truth = Associations.from_table(scene.associations).person_of_detections(dense)
        crop_lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
        estimated, to_true_world = self_calibrated(scene, dense, crop_lifted)
        for label, cameras, align in (("true", list(scene.rig), None), ("estimated", estimated, to_true_world)):
            rig = CameraRig.from_cameras(cameras)
            lifted = lift_detections(lifter, dense.keypoints_px, dense.scores, K=rig.K[dense.view])
            for s in settings:
                result = associate(dense, lifted, rig, TrackingConfig(fps=scene.config.fps, smoothing=s))
                m = scores(scene, dense, truth, result, align)
                key = (label, "off" if not s.enabled else f"scale {s.scale_px:g} px, acc {s.acceleration_mps2:g}, it {s.iterations}")
                table.setdefault(key, []).append(m)
                print(f"{name:6s} {label:9s} {key[1]:32s} MPJPE {m[0]:6.1f} mm  PCP {m[1]:5.1f} %  "
                      f"coverage {m[2]:5.1f} %  ({result.stage_seconds['smoothing']:.2f} s)", flush=True)
    print("\nmean over the scenes")
    for (label, setting), rows in table.items():
        m = np.mean(rows, axis=0)
        print(f"{label:9s} {setting:32s} MPJPE {m[0]:6.1f} mm  PCP {m[1]:5.1f} %  coverage {m[2]:5.1f} %")


if __name__ == "__main__":
    main()
