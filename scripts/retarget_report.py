"""Retarget CMU Daz BVH clips onto the body model and report the IK residuals and the time taken.

For every subject: one shape fit over all of its selected clips, then every clip (``humancal.retarget``).
Prints the per-clip residual table (mm: median, 95th percentile, maximum over frames and mapped joints), the
pooled median and 95th percentile over all clips, the per-joint medians and the times; writes under ``--out``
(never into the repository) the per-clip table (CSV), a figure of one clip, and with ``--motions`` the
canonical motions table (Parquet).

    python scripts/retarget_report.py                          # all BVH clips of the data root
    python scripts/retarget_report.py --subjects 02 05 --out /tmp/retarget --plot-clip 05_02
    python scripts/retarget_report.py --limit 3 --tiny         # a quick look
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd


def _bvh_paths(root: Path, subjects: list[str] | None, limit: int | None) -> dict[str, list[Path]]:
    by_subject: dict[str, list[Path]] = {}
    for folder in sorted(p for p in (root / "bvh_daz").iterdir() if p.is_dir()):
        if subjects and folder.name not in subjects:
            continue
        paths = sorted(folder.glob("*.bvh.gz")) + sorted(folder.glob("*.bvh"))
        if limit:
            paths = paths[:limit]
        if paths:
            by_subject[folder.name] = paths
    return by_subject


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", type=Path, default=None,
                        help="folder holding bvh_daz/ (default: humancal.settings.dataset_dir('cmu_mocap'))")
    parser.add_argument("--subjects", nargs="*", default=None, help="subject ids to keep (default: all)")
    parser.add_argument("--limit", type=int, default=None, help="at most this many clips per subject")
    parser.add_argument("--out", type=Path, default=Path("/tmp/humancal_retarget"), help="output folder")
    parser.add_argument("--plot-clip", default=None, help="clip to draw (default: the first)")
    parser.add_argument("--motions", action="store_true", help="also write the motions table (Parquet)")
    parser.add_argument("--tiny", action="store_true", help="RetargetConfig.tiny() instead of the default")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads (RetargetConfig)")
    args = parser.parse_args(argv)

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    logging.getLogger("anny").setLevel(logging.WARNING)
    import dataclasses

    from humancal.body import BodyModel
    from humancal.mocap import read_bvh
    from humancal.retarget import (
        RetargetConfig,
        clips_to_motions_table,
        fit_subject,
        plot_retarget,
        pooled_residual_mm,
        residual_summary,
        retarget_clip,
    )
    from humancal.settings import dataset_dir

    root = args.data_root or dataset_dir("cmu_mocap", required_for="scripts/retarget_report.py")
    by_subject = _bvh_paths(root, args.subjects, args.limit)
    if not by_subject:
        print(f"no BVH clips under {root / 'bvh_daz'} for subjects {args.subjects}", file=sys.stderr)
        return 1
    config = RetargetConfig.tiny() if args.tiny else RetargetConfig()
    config = dataclasses.replace(config, torch_threads=args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    body = BodyModel()

    start = time.perf_counter()
    read_s = shape_s = pose_s = 0.0
    results, seconds, originals = [], {}, {}
    for subject, paths in by_subject.items():
        t = time.perf_counter()
        clips = [read_bvh(path, include_end_sites=True) for path in paths]
        read_s += time.perf_counter() - t
        t = time.perf_counter()
        fit = fit_subject(clips, body, config)
        shape_s += time.perf_counter() - t
        for clip in clips:
            t = time.perf_counter()
            results.append(retarget_clip(clip, body, fit, config))
            seconds[clip.name] = time.perf_counter() - t
            pose_s += seconds[clip.name]
            if clip.name == (args.plot_clip or results[0].name):
                originals[clip.name] = clip
    total_s = time.perf_counter() - start

    summary = residual_summary(results)
    summary["seconds"] = summary["clip"].map(seconds)
    pooled = pooled_residual_mm(results)
    per_joint = pd.Series(
        np.median(np.concatenate([r.residual_mm for r in results]), axis=0), index=results[0].mapped_joint_names
    )
    frames = int(summary["frames"].sum())
    with pd.option_context("display.max_rows", None, "display.width", 120, "display.float_format", "{:.2f}".format):
        print(summary.to_string(index=False))
        print("\nmedian residual per mapped joint (mm):")
        print(per_joint.to_string())
    print(f"\nclips {len(results)}, subjects {len(by_subject)}, frames {frames} at {config.fps:.0f} fps")
    print(f"residual over all clips: median {pooled['median_mm']:.2f} mm, 95th percentile {pooled['p95_mm']:.2f} mm, "
          f"max {pooled['max_mm']:.1f} mm")
    print(f"time: total {total_s:.1f} s = read {read_s:.1f} s + shape fits {shape_s:.1f} s + pose fits {pose_s:.1f} s "
          f"({1000 * pose_s / frames:.2f} ms per frame), torch threads {args.threads}")

    summary.to_csv(args.out / "retarget_residuals.csv", index=False)
    name = args.plot_clip or results[0].name
    if name in originals:
        retargeted = next(r for r in results if r.name == name)
        frames_to_draw = np.linspace(0, retargeted.frames - 1, 3).round().astype(int).tolist()
        png = plot_retarget(originals[name], retargeted, frames_to_draw, args.out / f"retarget_{name}.png")
        print(f"figure: {png}")
    else:
        print(f"--plot-clip {name!r} is not among the retargeted clips", file=sys.stderr)
    if args.motions:
        motions = clips_to_motions_table(results)
        motions.to_parquet(args.out / "motions.parquet")
        print(f"motions table: {args.out / 'motions.parquet'} ({len(motions)} rows)")
    print(f"table: {args.out / 'retarget_residuals.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
