"""Run time of the association's affinity on the benchmark workload: 900 frames, 5 views, 4 people.

Builds the synthetic ``benchmark`` scene (with its false positives), lifts every detection with the shipped
lifter into the ground-truth cameras' frames, then times :func:`humancal.association.pair_affinities` (every
cross-view pair of every frame) and the per-frame matrices, ``--repeats`` times with ``--threads`` BLAS threads;
prints the median and the spread, the size of the input and the ROC AUC of same-person pairs (ground-truth
identities), for the combined affinity and for ``epipolar_only``; ``--wrong-cameras`` also scores them with every
focal length 3 % off and every rotation 1 degree off (seeded).

    python scripts/bench_affinity.py [--repeats 5] [--threads 2] [--wrong-cameras]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import threadpoolctl
import torch
from scipy.stats import rankdata

from humancal.association import AffinityConfig, pair_affinities
from humancal.body import BodyModel
from humancal.camera import CameraRig
from humancal.geometry.rotations import axis_angle_to_rotmat
from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
from humancal.synthetic import generate_scene, preset
from humancal.tables.associations import Associations
from humancal.tables.detections import detections_to_dense


def _roc_auc(positive: np.ndarray, score: np.ndarray) -> float:
    ranks = rankdata(score)
    n1, n0 = positive.sum(), (~positive).sum()
    return float((ranks[positive].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def _wrong_cameras(rig: CameraRig, focal_pct: float = 3.0, angle_deg: float = 1.0, seed: int = 0) -> CameraRig:
    """Every focal length off by +-focal_pct % and every rotation by angle_deg about a random axis."""
    rng = np.random.default_rng(seed)
    K = rig.K.copy()
    factor = 1.0 + 0.01 * focal_pct * rng.choice([-1.0, 1.0], len(rig))
    K[:, 0, 0] *= factor
    K[:, 1, 1] *= factor
    axis = rng.normal(size=(len(rig), 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    R = axis_angle_to_rotmat(axis, np.full(len(rig), np.deg2rad(angle_deg))) @ rig.R_cam_from_world
    return CameraRig(K, R, -np.einsum("vij,vj->vi", R, rig.centers_world_m), rig.distortion, rig.image_size_px)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--wrong-cameras", action="store_true", help="also score with perturbed cameras")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    with threadpoolctl.threadpool_limits(args.threads):
        scene = generate_scene(preset("benchmark"), BodyModel(), sequence="benchmark")
        dense = detections_to_dense(scene.detections)
        person = Associations.from_table(scene.associations).person_of_detections(dense)
        rig = CameraRig.from_cameras(scene.rig)
        start = time.perf_counter()
        lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores,
                                 K=rig.K[dense.view])
        lift_s = time.perf_counter() - start
        print(f"workload: {len(np.unique(dense.frame))} frames, {len(rig)} views, {scene.person_ids.size} people, "
              f"{len(dense)} detections ({int((person < 0).sum())} false positives); lift {lift_s:.2f} s")
        for name, config in (("association", AffinityConfig()), ("epipolar_only", AffinityConfig.epipolar_only())):
            pairs_s, matrices_s = [], []
            for _ in range(args.repeats):
                start = time.perf_counter()
                pairs = pair_affinities(dense, lifted, rig, config)
                pairs_s.append(time.perf_counter() - start)
                start = time.perf_counter()
                pairs.matrices()
                matrices_s.append(time.perf_counter() - start)
            a, b = person[pairs.rows_a], person[pairs.rows_b]
            auc = _roc_auc((a == b) & (a >= 0), pairs.combined)
            print(f"{name}: pair_affinities {statistics.median(pairs_s):.3f} s (min {min(pairs_s):.3f}, max "
                  f"{max(pairs_s):.3f}) over {len(pairs.rows_a)} cross-view pairs; per-frame matrices "
                  f"{statistics.median(matrices_s):.3f} s; same-person ROC AUC {auc:.4f}")
            if args.wrong_cameras:
                wrong = pair_affinities(dense, lifted, _wrong_cameras(rig), config)
                a, b = person[wrong.rows_a], person[wrong.rows_b]
                print(f"{name}, cameras 3 % / 1 deg off: same-person ROC AUC "
                      f"{_roc_auc((a == b) & (a >= 0), wrong.combined):.4f}")


if __name__ == "__main__":
    main()
