"""Run time and accuracy of the whole association (affinity, matching, tracking, triangulation) on the benchmark
workload: 900 frames, 5 views, 4 people (or another size of the same scene: ``--views``, ``--people``, ``--frames``).

Builds the synthetic ``benchmark`` scene (with its false positives and left-right flips), lifts every detection with
the shipped lifter into the ground-truth cameras' frames (not timed as association), then runs
:func:`humancal.association.associate` ``--repeats`` times with ``--threads`` BLAS threads and prints the per-stage
seconds of the fastest run and, against the true identities: pairwise precision and recall of same-person
detection pairs across views, identity switches, false positives rejected and the number of people.

    python scripts/bench_association.py [--repeats 3] [--threads 2] [--match-threshold 0.3] [--no-temporal] \
        [--views 31 --people 8 --frames 60]
"""

from __future__ import annotations

import argparse

import numpy as np
import threadpoolctl
import torch

from humancal.association import TrackingConfig, associate
from humancal.body import BodyModel
from humancal.camera import CameraRig
from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
from humancal.synthetic import generate_scene, preset
from humancal.tables.associations import Associations
from humancal.tables.detections import detections_to_dense


def pairwise_scores(truth: np.ndarray, found: np.ndarray, frame: np.ndarray, view: np.ndarray) -> tuple[float, float]:
    """(precision, recall) of the same-person pairs of detections of one frame in different views."""
    order = np.argsort(frame, kind="stable")
    truth, found, frame, view = truth[order], found[order], frame[order], view[order]
    _, start, count = np.unique(frame, return_index=True, return_counts=True)
    a = np.concatenate([s + np.triu_indices(c, 1)[0] for s, c in zip(start, count)])
    b = np.concatenate([s + np.triu_indices(c, 1)[1] for s, c in zip(start, count)])
    keep = view[a] != view[b]
    a, b = a[keep], b[keep]
    same = (truth[a] == truth[b]) & (truth[a] >= 0)
    said = (found[a] == found[b]) & (found[a] >= 0)
    return float((same & said).sum() / max(said.sum(), 1)), float((same & said).sum() / max(same.sum(), 1))


def identity_switches(truth: np.ndarray, found: np.ndarray, frame: np.ndarray) -> int:
    """Changes of the id given to each true person from one of its frames to the next (majority id per frame)."""
    switches = 0
    for person in np.unique(truth[truth >= 0]):
        mine = (truth == person) & (found >= 0)
        frames = np.unique(frame[mine])
        ids = [np.bincount(found[mine & (frame == f)]).argmax() for f in frames]
        switches += int((np.diff(ids) != 0).sum())
    return switches


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--match-threshold", type=float, default=TrackingConfig().match_threshold)
    parser.add_argument("--no-temporal", action="store_true", help="without the temporal term")
    parser.add_argument("--views", type=int, default=None, help="cameras (default: the benchmark scene's 5)")
    parser.add_argument("--people", type=int, default=None, help="people (default: the benchmark scene's 4)")
    parser.add_argument("--frames", type=int, default=None, help="frames (default: the benchmark scene's 900)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = TrackingConfig(match_threshold=args.match_threshold, temporal=not args.no_temporal)
    with threadpoolctl.threadpool_limits(args.threads):
        sizes = {"num_views": args.views, "num_people": args.people, "num_frames": args.frames}
        scene = generate_scene(preset("benchmark", **{k: v for k, v in sizes.items() if v is not None}), BodyModel(),
                               sequence="benchmark")
        dense = detections_to_dense(scene.detections)
        truth = Associations.from_table(scene.associations).person_of_detections(dense)
        rig = CameraRig.from_cameras(scene.rig)
        lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores,
                                 K=rig.K[dense.view])
        print(f"workload: {len(np.unique(dense.frame))} frames, {len(rig)} views, {scene.person_ids.size} people, "
              f"{len(dense)} detections ({int((truth < 0).sum())} false positives)")
        runs = [associate(dense, lifted, rig, config) for _ in range(args.repeats)]
    best = min(runs, key=lambda r: r.stage_seconds["total"])
    stages = ", ".join(f"{k} {v:.3f}" for k, v in best.stage_seconds.items())
    totals = ", ".join(f"{r.stage_seconds['total']:.2f}" for r in runs)
    print(f"seconds (fastest of {args.repeats}): {stages}; all totals: {totals}")
    precision, recall = pairwise_scores(truth, best.person_id, dense.frame, dense.view)
    fp = truth < 0
    print(f"match_threshold {config.match_threshold}, temporal {config.temporal}: pairwise precision {precision:.4f}, "
          f"recall {recall:.4f}; identity switches {identity_switches(truth, best.person_id, dense.frame)}; "
          f"false positives rejected {int((best.person_id[fp] < 0).sum())} / {int(fp.sum())}; people "
          f"{best.num_people} (true {scene.person_ids.size}); warnings {list(best.warnings)}")


if __name__ == "__main__":
    main()
