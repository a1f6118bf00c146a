"""Grouping quality of the Shelf reader: recall, fragment rate and joint error per view and overall.

Reads the Shelf folder (``humancal.settings.dataset_dir("shelf_4dassoc")``, i.e. ``$HUMANCAL_DATA_DIR/shelf_4dassoc``
or ``../shared/data/shelf_4dassoc`` beside the checkout), groups the OpenPose candidates with the default settings
and, with ``--plain``, also with the plain greedy PAF tree (no fragment repair), then prints the figures of
``evaluation.detection_quality`` and the wall times.

    python scripts/shelf_grouping_report.py [--plain] [--csv metrics.csv]
"""

from __future__ import annotations

import argparse
import time

import pandas as pd

from evaluation.detection_quality import evaluate_grouping
from humancal.datasets.shelf import load_shelf
from humancal.grouping import GroupingConfig
from humancal.settings import dataset_dir

_SHOWN = ("detection_recall", "detection_fragment_rate", "median_joint_error_px", "gt_person_views", "detections")


def _report(name: str, config: GroupingConfig) -> pd.DataFrame:
    start = time.perf_counter()
    shelf = load_shelf(dataset_dir("shelf_4dassoc", required_for="the Shelf grouping report"), config)
    load_s = time.perf_counter() - start
    start = time.perf_counter()
    metrics = evaluate_grouping(shelf.detections, shelf.gt_poses, shelf.cameras, dataset="shelf", method=name).metrics
    eval_s = time.perf_counter() - start
    values = metrics.assign(scope=[f"view_{v}" if pd.notna(v) else "overall" for v in metrics["view"]])
    values = values.set_index(["metric", "scope"])["value"]
    scopes = ["overall"] + [f"view_{v}" for v in range(shelf.num_views)]
    table = pd.DataFrame({m: [values[(m, s)] for s in scopes] for m in _SHOWN}, index=scopes)
    formats = {m: "{:.4f}" for m in _SHOWN[:2]} | {_SHOWN[2]: "{:.2f}"} | {m: "{:.0f}" for m in _SHOWN[3:]}
    print(
        f"\n{name}: {shelf.num_frames} frames x {shelf.num_views} views; "
        f"load_shelf {load_s:.1f} s (parse + group), evaluation {eval_s:.1f} s"
    )
    print(table.to_string(formatters={m: f.format for m, f in formats.items()}))
    return metrics


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plain", action="store_true", help="also report the plain greedy tree (no repair)")
    parser.add_argument("--csv", help="write the metrics table(s) to this CSV file")
    args = parser.parse_args()
    tables = [_report("grouping", GroupingConfig())]
    if args.plain:
        tables.append(_report("grouping_plain_greedy", GroupingConfig(reattach=False, merge=None)))
    if args.csv:
        pd.concat(tables, ignore_index=True).to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
