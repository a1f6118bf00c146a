"""The body fit's interpenetration term on two people in close contact: off against on, beside the truth.

The synthetic generator keeps people at least 0.7 m apart (``humancal.synthetic.paths``), so the close-contact
scene is written here from its public pieces: one activity schedule and one ground path for a couple walking,
turning, standing, gesturing and crouching together side by side, the two roots ``--separation`` metres apart
across the heading (each with their own body, gait style and sway); feet put on the floor as
``humancal.synthetic.generate_motions`` does. The scene is seen by the demo preset's ring rig and simulated
detector (``--views`` cameras, its noise), lifted with the shipped lifter and associated with the true cameras,
then fitted twice with the shipped motion prior and the true cameras (held: ``--cameras fixed``, so that only the
interpenetration term differs): ``weight_interpenetration=0`` (off) and ``--weight`` (on; the pipeline's default
is off, ``docs/refinement.md``).

Defaults: seed 3 draws a walk for the first 150 frames (seed 0 stands and turns); 0.55 m between the roots is about
as close as these anny adults get side by side without their meshes interpenetrating (the true bodies' penetration
row: under a millimetre; with seed 0's people the true meshes overlap by 35 mm at 0.45 m and 96 mm at 0.35 m).

Prints one row per method: the meshes' penetration (``evaluation.contact_metrics``: deepest vertex inside the other
body and the shared volume, means over ``--eval-frames`` evenly spread frames), the MPJPE of the fitted keypoints
against the true ones (each fitted person matched to the true person most of their detections belong to), and the
fit's seconds; the ground truth's own row is the penetration of the true bodies.

    python scripts/contact_bench.py [--frames 150] [--separation 0.55] [--views 4] [--seed 3] [--threads 2]
        [--eval-frames 30] [--cameras fixed] [--weight 1] [--set FIELD=VALUE ...] [--methods off,on]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from evaluation.contact_metrics import penetration_figures
from humancal.association import associate, to_associations_table, to_skeletons_table
from humancal.body import BodyModel, RestSkeleton
from humancal.camera import CameraRig
from humancal.fitting import BodyFitConfig, FittedMotions, body_observations, fit_bodies
from humancal.keypoints import joint_indices
from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
from humancal.prior import shipped_prior
from humancal.synthetic import make_rig, preset, sample_people, simulate_detections
from humancal.synthetic.activities import activity_track, plan_activities
from humancal.synthetic.motions import FOOT_JOINTS, Motions, person_pose
from humancal.synthetic.paths import Paths, simulate_paths
from humancal.tables.associations import Associations
from humancal.tables.detections import DenseDetections

_FOOT_INDEX = joint_indices(list(FOOT_JOINTS))
_ANKLE_INDEX = joint_indices(["left_ankle", "right_ankle"])


def couple_paths(centre: Paths, separation_m: float, fps: float) -> Paths:
    """The two people's ground paths: ``separation_m`` apart across the couple's heading (person 0 on the left)."""
    heading = centre.heading_rad[0]
    left = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)  # (F, 2)
    position = centre.position_m[0][None] + np.array([0.5, -0.5])[:, None, None] * separation_m * left[None]
    velocity = np.gradient(position, 1.0 / fps, axis=1) if position.shape[1] > 1 else np.zeros_like(position)
    return Paths(position_m=position, heading_rad=np.stack([heading, heading]),
                 speed_mps=np.linalg.norm(velocity, axis=-1))


def couple_motions(body: BodyModel, rest: RestSkeleton, num_frames: int, fps: float, area_size_m: tuple[float, float],
                   separation_m: float, rng: np.random.Generator) -> Motions:
    """Two people doing the same activities side by side (module docstring); the variant of
    ``humancal.synthetic.generate_motions`` with the couple's paths instead of independent ones."""
    track = activity_track(plan_activities(num_frames, fps, rng, "mixed"), num_frames, fps, rng)
    paths = couple_paths(simulate_paths([track], area_size_m, fps, rng, margin_m=0.4 + separation_m), separation_m,
                         fps)
    heads = rest.bone_heads_m.detach().double().cpu().numpy()
    rotmats = np.empty((2, num_frames, body.num_posed_bones, 3, 3))
    root_xy = np.empty((2, num_frames, 2))
    for p in range(2):
        rotmats[p], root_xy[p] = person_pose(body, heads[p], track, paths, p, fps, rng)
    rotmats_t = torch.as_tensor(rotmats, dtype=body.dtype)
    translation = np.concatenate([root_xy, np.zeros((2, num_frames, 1))], axis=-1)

    def keypoints() -> np.ndarray:
        with torch.no_grad():
            return body.keypoints(rest, rotmats_t, torch.as_tensor(translation, dtype=body.dtype)).double().numpy()

    points = keypoints()
    translation[..., 2] = -points[..., _FOOT_INDEX, 2].min(axis=-1)  # the lowest foot point on the floor
    anchor = np.clip(4.0 * track.crouch, 0.0, 1.0)[None, :, None]  # crouching: the ankles stay where they stood
    translation[..., :2] -= anchor * (points[..., _ANKLE_INDEX, :2].mean(axis=-2) - root_xy)
    translation = torch.as_tensor(translation, dtype=body.dtype).double().numpy()
    return Motions(bone_rotmats_local=rotmats_t.double().numpy(), root_translation_m=translation,
                   keypoints_world_m=keypoints(), activity=np.stack([track.label, track.label]),
                   heading_rad=paths.heading_rad.copy())


def dense_detections(detector, rng: np.random.Generator) -> tuple[DenseDetections, np.ndarray]:
    """The simulated detections as :class:`DenseDetections` (ids shuffled within each frame and view), and the
    (D,) true person of each row (-1: a false positive)."""
    key = rng.random(len(detector.frame))
    order = np.lexsort((key, detector.view, detector.frame))
    frame, view = detector.frame[order], detector.view[order]
    first = np.ones(len(order), bool)
    first[1:] = (frame[1:] != frame[:-1]) | (view[1:] != view[:-1])
    det_id = np.arange(len(order)) - np.maximum.accumulate(np.where(first, np.arange(len(order)), 0))
    present = detector.present[order]
    keypoints = np.where(present[..., None], detector.keypoints_px[order], np.nan)
    scores = np.where(present, detector.scores[order], 0.0)
    return DenseDetections(frame, view, det_id, keypoints, scores), detector.person_id[order]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--separation", type=float, default=0.55, help="distance of the two roots, metres")
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--seed", type=int, default=3, help="scene seed (3: a walk side by side; 0 stands and turns)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--eval-frames", type=int, default=30, help="frames whose meshes are tested")
    parser.add_argument("--cameras", default="fixed", help="BodyFitConfig.cameras")
    parser.add_argument("--weight", type=float, default=1.0, help="weight_interpenetration of the 'on' fit")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="change a BodyFitConfig field of both fits (repeatable), e.g. --set contact_scale_m=0.02")
    parser.add_argument("--methods", default="off,on", help="which fits to run, of off,on")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = preset("demo", num_people=2, num_views=args.views, num_frames=args.frames, seed=args.seed)
    rng_people, rng_motion, rng_rig, rng_noise, rng_ids = np.random.default_rng(config.seed).spawn(5)

    body = BodyModel()
    people = sample_people(body, 2, rng_people, config.height_range_m)
    with torch.no_grad():
        rest = body.rest_skeleton(torch.as_tensor(people.phenotypes, dtype=body.dtype))
    motions = couple_motions(body, rest, config.num_frames, config.fps, config.area_size_m, args.separation,
                             rng_motion)
    cameras = make_rig(config, rng_rig)
    detector = simulate_detections(motions.keypoints_world_m, people.height_m, cameras, config.noise, rng_noise)
    dense, truth = dense_detections(detector, rng_ids)

    rig = CameraRig.from_cameras(cameras)
    lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores, K=rig.K[dense.view])
    result = associate(dense, lifted, rig)
    found_table, skeletons = to_associations_table(result, "contact"), to_skeletons_table(result, "contact")
    observations, warnings = body_observations(dense, found_table, skeletons, len(rig))
    found = Associations.from_table(found_table).person_of_detections(dense)
    truth_of = {int(pid): int(np.bincount(truth[(found == pid) & (truth >= 0)], minlength=2).argmax())
                for pid in observations.person_ids}
    print(f"scene: {args.frames} frames, {args.views} views, 2 people {args.separation:.2f} m apart (heights "
          f"{people.height_m.round(2).tolist()} m); association found {observations.num_people} people "
          f"(true persons {list(truth_of.values())}){'; ' + '; '.join(warnings) if warnings else ''}", flush=True)

    truth_motions = FittedMotions(
        person_ids=np.arange(2), frames=np.arange(config.num_frames), present=np.ones((2, config.num_frames), bool),
        phenotypes=people.phenotypes, bone_rotmats_local=motions.bone_rotmats_local,
        root_translation_m=motions.root_translation_m, keypoints_world_m=motions.keypoints_world_m, fps=config.fps)
    rows = {"ground truth": {**penetration_figures(body, truth_motions, args.eval_frames), "mpjpe_mm": 0.0,
                             "fit_s": float("nan")}}
    prior = shipped_prior("motion_prior")[0]
    base = BodyFitConfig().replace(cameras=args.cameras)
    for item in args.set:
        name, _, value = item.partition("=")
        base = base.replace(**{name: type(getattr(base, name))(value)})
    methods = {"off": base.replace(weight_interpenetration=0.0), "on": base.replace(weight_interpenetration=args.weight)}
    for name in args.methods.split(","):
        fit_config = methods[name]
        start = time.perf_counter()
        fit = fit_bodies(body, observations, rig, prior, fit_config, fps=config.fps)
        seconds = time.perf_counter() - start
        fitted = fit.motions
        gt = motions.keypoints_world_m[[truth_of[int(pid)] for pid in fitted.person_ids]][:, fitted.frames]
        mpjpe = 1e3 * float(np.linalg.norm(fitted.keypoints_world_m - gt, axis=-1)[fitted.present].mean())
        rows[f"interpenetration {name} (weight {fit_config.weight_interpenetration:g})"] = {
            **penetration_figures(body, fitted, args.eval_frames), "mpjpe_mm": mpjpe, "fit_s": seconds}
        print(f"fit {name}: {seconds:.1f} s, loss terms "
              f"{ {k: round(v, 4) for k, v in fit.loss_terms.items()} }", flush=True)
    print(f"\n{'':38s} {'depth mm':>9s} {'volume cm3':>11s} {'MPJPE mm':>9s} {'fit s':>7s}")
    for name, r in rows.items():
        print(f"{name:38s} {r['penetration_depth_mm']:9.1f} {r['penetration_volume_cm3']:11.1f} "
              f"{r['mpjpe_mm']:9.1f} {r['fit_s']:7.1f}")
    print(f"(penetration: mean over {int(rows['ground truth']['evaluated_frames'])} evenly spread frames of the "
          f"deepest vertex inside the other body and of the shared volume, on the anny meshes)")


if __name__ == "__main__":
    main()
