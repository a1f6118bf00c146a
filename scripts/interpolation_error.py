"""How far the detections of unsynchronised views are from the people once put on view 0's clock: the nearest frame
against detections interpolated between frames (``docs/capture.md``, "Unsynchronised videos").

Each scene is a phone rig of ``scripts/sync_sweep.py --clocks consumer`` (5-10 views at 25, 30, 50 or 60 fps,
started up to 2 s apart, 5-15 s, people who walk or sit), moved to view 0's frames with the TRUE time offsets by
:func:`humancal.sync.apply_time_offsets`, once taking each view's nearest frame and once interpolating. Every kept
detection of a view other than view 0 is scored against the true keypoints of the person it shows at the time of
view 0's frame, projected through the true camera (its lens included): the mean pixel distance over its detected
joints, and the same in the person's size (the larger side of the box of their projected keypoints), so that near
and far people count alike. A detection is given the person whose projection is nearest; one more than half a
person's size from every person (a false positive) is left out. The detector's own noise is in both figures; the
difference between them is the timing, and the average of two noisy detections; ``--clean`` turns the detector's
jitter and outliers off, so that what is left is the timing alone (and the detector's misses and false positives).

    python scripts/interpolation_error.py --scenes 20 --seed 0 [--clean] [--out rows.jsonl]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def score_scene(seed: int, body, clean: bool = False) -> dict:
    """Nearest-frame and interpolated detections of consumer scene ``seed`` against the truth; one dict of figures."""
    from sync_sweep import _consumer_scene

    from humancal.camera.model import project_points
    from humancal.sync import apply_time_offsets
    from humancal.synthetic.clocks import keypoints_at
    from humancal.synthetic.detector_noise import DetectorNoise
    from humancal.tables.detections import detections_to_dense

    noise = DetectorNoise(jitter_std_frac=0.0, outlier_rate=0.0) if clean else None
    scene, detections, fps, offsets_s, row = _consumer_scene(seed, body, noise)
    clocks = scene.clocks
    truth = keypoints_at(scene.keypoints_world_m, clocks, 0)  # (P, N_0, 23, 3) at view 0's frames
    first = int(clocks.frames[0][0])
    out = dict(row, seed=seed, clean=clean)
    for mode in ("nearest", "interpolated"):
        applied = apply_time_offsets(detections, offsets_s, fps, interpolate=mode == "interpolated")
        dense = detections_to_dense(applied.detections)
        pixels, sizes = [], []
        for v in range(1, len(fps)):
            rows = np.flatnonzero(dense.view == v)
            index = dense.frame[rows] - first
            inside = (index >= 0) & (index < truth.shape[1])
            rows, index = rows[inside], index[inside]
            projected, _ = project_points(scene.rig[v], truth[:, index])  # (P, D, 23, 2)
            valid = dense.valid[rows]
            dist = np.linalg.norm(projected - dense.keypoints_px[rows][None], axis=-1)  # (P, D, 23)
            mean = np.where(valid[None], dist, 0.0).sum(-1) / np.maximum(valid.sum(-1), 1)[None]
            person = np.nanargmin(np.where(np.isfinite(mean), mean, np.inf), axis=0)
            size = np.ptp(projected, axis=2).max(axis=-1)  # (P, D)
            best = mean[person, np.arange(len(rows))]
            best_size = size[person, np.arange(len(rows))]
            true = best < 0.5 * best_size
            pixels.append(best[true])
            sizes.append(best[true] / best_size[true])
        pixels, sizes = np.concatenate(pixels), np.concatenate(sizes)
        out[mode] = {"detections": int(len(pixels)), "median_px": float(np.median(pixels)),
                     "mean_px": float(np.mean(pixels)), "p90_px": float(np.percentile(pixels, 90)),
                     "median_size_pct": float(100 * np.median(sizes)),
                     "interpolated": int(applied.interpolated.sum()),
                     "residual_frames_max": float(applied.residual_frames.max())}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0, help="scene i is sync_sweep's consumer scene S * 100000 + i")
    parser.add_argument("--clean", action="store_true", help="no detector jitter or outliers: the timing alone")
    parser.add_argument("--out", type=Path, help="one JSON line per scene (resumable)")
    args = parser.parse_args()
    from humancal.body import BodyModel

    done = {}
    if args.out and args.out.exists():
        done = {r["seed"]: r for r in map(json.loads, args.out.read_text().splitlines())}
    body = BodyModel()
    rows = []
    for i in range(args.scenes):
        seed = args.seed * 100000 + i
        row = done.get(seed) or score_scene(seed, body, args.clean)
        if seed not in done and args.out:
            with args.out.open("a") as f:
                f.write(json.dumps(row) + "\n")
        rows.append(row)
        print(f"scene {seed}: {row['behaviour']}, {row['fps']} fps: median "
              f"{row['nearest']['median_px']:.2f} px nearest, {row['interpolated']['median_px']:.2f} px interpolated",
              flush=True)
    for mode in ("nearest", "interpolated"):
        for behaviour in ("mixed", "seated", None):
            chosen = [r for r in rows if behaviour is None or r["behaviour"] == behaviour]
            if not chosen:
                continue
            mean = np.mean([r[mode]["mean_px"] for r in chosen])
            median = np.median([r[mode]["median_px"] for r in chosen])
            size = np.median([r[mode]["median_size_pct"] for r in chosen])
            print(f"{mode:>12} {behaviour or 'all':>6}: {len(chosen)} scenes, median of scene medians {median:.2f} px "
                  f"({size:.2f} % of a person's size), mean of scene means {mean:.2f} px")


if __name__ == "__main__":
    main()
