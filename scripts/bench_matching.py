"""Speed and accuracy of the cycle-consistent matching on synthetic affinity matrices.

Every frame holds ``people`` people, each seen by each of ``views`` views with probability 0.9, plus about
``false_positives`` false detections per view; affinities are 0.8 within a person and 0.2 otherwise, plus Gaussian
noise (``--noise``), clipped to [0, 1]. The affinities of a sequence drift over time (an AR(1) noise), so that the
previous frame's solution is a meaningful warm start. Modes:

- ``batched``: all frames in one :func:`match_frames` call (parts of the frames solved together, cold starts);
- ``whole``: the same without splitting frames into their connected parts (one problem per frame);
- ``warm``: frame after frame, each warm-started from the previous frame's solution (:func:`carry_over`).

``--scene`` instead matches the real affinities (:func:`humancal.association.pair_affinities`, ground-truth cameras,
the shipped lifter) of the synthetic ``benchmark`` scene: 900 frames, 5 views, 4 people, with its false positives.

Run: ``.venv/bin/python scripts/bench_matching.py`` (about a minute on 2 cores); ``--scene`` (a few minutes).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from humancal.association.cycle_matching import MatchingConfig, carry_over, match_frame, match_frames

CASES = (  # (label, views, people, false positives per view, frames)
    ("N~10", 3, 3, 0.3, 300),
    ("N~20", 5, 4, 0.3, 300),
    ("N~30", 6, 5, 0.5, 300),
    ("N~60", 10, 6, 0.5, 100),
    ("N~150 (31 views)", 31, 4, 1.0, 30),
)


def synthetic_sequence(rng: np.random.Generator, views: int, people: int, false_positives: float, frames: int,
                       noise: float) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """One layout of detections and its affinities over ``frames`` frames.

    Returns:
        view: (N,) int; person: (N,) int (-1: false positive); affinities: per frame (N, N).
    """
    view, person = [], []
    for v in range(views):
        seen = np.flatnonzero(rng.random(people) < 0.9)
        fp = rng.poisson(false_positives)
        view += [v] * (len(seen) + fp)
        person += seen.tolist() + [-1] * fp
    view, person = np.array(view, dtype=np.int64), np.array(person, dtype=np.int64)
    n = len(view)
    same = (person[:, None] == person[None, :]) & (person[:, None] >= 0)
    mean = np.where(same, 0.8, 0.2)
    drift = rng.standard_normal((n, n))
    out = []
    for _ in range(frames):
        drift = 0.9 * drift + np.sqrt(1 - 0.9**2) * rng.standard_normal((n, n))
        w = np.triu(np.clip(mean + noise * drift, 0.0, 1.0), 1)
        w = w + w.T
        w[view[:, None] == view[None, :]] = 0.0
        np.fill_diagonal(w, 1.0)
        out.append(w)
    return view, person, out


def pairwise_scores(person: np.ndarray, cluster: np.ndarray) -> tuple[int, int, int]:
    """(true positive, false positive, false negative) same-cluster pairs against the true persons."""
    iu = np.triu_indices(len(person), 1)
    truth = ((person[:, None] == person[None, :]) & (person[:, None] >= 0))[iu]
    found = ((cluster[:, None] == cluster[None, :]) & (cluster[:, None] >= 0))[iu]
    return int((truth & found).sum()), int((~truth & found).sum()), int((truth & ~found).sum())


def scene_benchmark(repeats: int = 3) -> None:
    """Time and score the matching on the real affinities of the synthetic benchmark scene."""
    import threadpoolctl
    import torch

    from humancal.association import AffinityConfig, pair_affinities
    from humancal.body import BodyModel
    from humancal.camera import CameraRig
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset
    from humancal.tables.associations import Associations
    from humancal.tables.detections import detections_to_dense

    torch.set_num_threads(2)
    with threadpoolctl.threadpool_limits(2):
        scene = generate_scene(preset("benchmark"), BodyModel(), sequence="benchmark")
        dense = detections_to_dense(scene.detections)
        person = Associations.from_table(scene.associations).person_of_detections(dense)
        rig = CameraRig.from_cameras(scene.rig)
        lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores,
                                 K=rig.K[dense.view])
    for name, affinity_config in (("association", AffinityConfig()), ("epipolar_only", AffinityConfig.epipolar_only())):
        pairs = pair_affinities(dense, lifted, rig, affinity_config)
        matrices = pairs.matrices()
        rows = [pairs.frame_rows(int(f)) for f in pairs.frames]
        views, persons = [dense.view[r] for r in rows], [person[r] for r in rows]
        for threshold in (0.3, 0.5):
            for decompose in (True, False):
                config = MatchingConfig(match_threshold=threshold, decompose=decompose)
                seconds = []
                for _ in range(repeats):
                    start = time.perf_counter()
                    result = match_frames(views, matrices, config)
                    seconds.append(time.perf_counter() - start)
                tp, fp, fn = np.sum([pairwise_scores(p, m.cluster) for p, m in zip(persons, result)], axis=0)
                false = np.concatenate(persons) < 0
                rejected = (np.concatenate([m.cluster for m in result]) < 0) & false
                its = np.array([m.iterations for m in result])
                print(f"{name:>13} threshold {threshold} decompose {decompose!s:>5}: {min(seconds):.3f} s "
                      f"({len(result)} frames, N {np.mean([len(v) for v in views]):.1f}); pairwise P "
                      f"{tp / max(tp + fp, 1):.4f} R {tp / max(tp + fn, 1):.4f}; false positives unmatched "
                      f"{rejected.sum()}/{false.sum()}; iterations mean {its.mean():.1f} max {its.max()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise", type=float, default=0.1, help="affinity noise standard deviation")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames-5x4", type=int, default=900, help="frames of the 5-view 4-person sequence")
    parser.add_argument("--scene", action="store_true", help="real affinities of the synthetic benchmark scene")
    args = parser.parse_args()
    if args.scene:
        scene_benchmark()
        return
    rng = np.random.default_rng(args.seed)
    cases = (*CASES, ("5 views x 4 people", 5, 4, 0.3, args.frames_5x4))
    print(f"noise {args.noise}; ms per frame (total s); pairwise precision / recall (batched); mean iterations")
    print(f"{'case':>20} {'N':>6} {'frames':>6} | {'batched':>16} | {'whole':>16} | {'warm':>16} | {'P':>6} {'R':>6} "
          f"| iterations whole, warm")
    for label, views, people, fps, frames in cases:
        # Several sequences of 30 frames, so that the layouts (and N) vary.
        seqs = [synthetic_sequence(rng, views, people, fps, 30, args.noise) for _ in range(max(1, frames // 30))]
        flat_v = [v for v, _, ws in seqs for _ in ws]
        flat_w = [w for _, _, ws in seqs for w in ws]
        n_mean = np.mean([len(v) for v in flat_v])
        timings = {}
        for mode, config in (("batched", MatchingConfig()), ("whole", MatchingConfig(decompose=False))):
            start = time.perf_counter()
            result = match_frames(flat_v, flat_w, config)
            timings[mode] = time.perf_counter() - start
            if mode == "whole":
                cold_iterations = np.mean([m.iterations for m in result])
            if mode == "batched":
                counts = np.sum([pairwise_scores(p, m.cluster) for (_, p, ws), m in
                                 zip([s for s in seqs for _ in s[2]], result)], axis=0)
        start = time.perf_counter()
        warm_iterations = []
        for v, _, ws in seqs:
            previous = None
            for w in ws:
                warm = None if previous is None else carry_over(previous, np.arange(len(v)))
                previous = match_frame(v, w, MatchingConfig(decompose=False), warm)
                warm_iterations.append(previous.iterations)
        timings["warm"] = time.perf_counter() - start
        cells = " | ".join(f"{1e3 * timings[m] / len(flat_v):7.2f} ({timings[m]:6.2f})" for m in
                           ("batched", "whole", "warm"))
        tp, fp, fn = counts
        print(f"{label:>20} {n_mean:6.1f} {len(flat_v):6d} | {cells} | {tp / max(tp + fp, 1):6.3f} "
              f"{tp / max(tp + fn, 1):6.3f} | {cold_iterations:5.1f} {np.mean(warm_iterations):5.1f}")


if __name__ == "__main__":
    main()
