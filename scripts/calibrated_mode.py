"""Calibrated mode through the command line, scored against a dataset's ground truth.

A dataset partition with ground truth (the synthetic demo, Shelf) is handed to ``humancal add`` the way a user with
calibrated cameras would hand over a capture: its detections as OpenPose folders, its true cameras as a Pose2Sim
file given with ``--cameras`` (used by the method: no calibration). ``humancal update`` then associates and fits
with those cameras held. The capture has no ground truth of its own, so this script scores its ``skeletons3d`` and
``fitted_motions`` against the source partition's, with the same protocol as the source's metric table
(``evaluation.body_metrics.pipeline_body_table``), and prints them beside the source's ``skeletons3d_gt_cameras``
rows (its association redone with the true cameras) and, when ``humancal benchmark`` has stored it, its
``gt_cameras`` rows (the body fit with the true cameras held).

    python scripts/calibrated_mode.py --partition synthetic__demo
    python scripts/calibrated_mode.py --partition shelf__test      # needs the data root's shelf_4dassoc

The source partition must have been materialized (``humancal update --partition P``); the capture is registered as
``calmode_<dataset>__capture`` in the state dir (removed first when it exists) and its files written under
``--work`` (default: a temporary folder).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

METRICS = ("mpjpe_mm", "pa_mpjpe_mm", "pcp_avg")


def _run(*args: str) -> None:
    print("$ humancal " + " ".join(args), flush=True)
    done = subprocess.run([sys.executable, "-m", "pipelines.cli", *args], text=True)
    if done.returncode:
        raise SystemExit(f"humancal {args[0]} failed ({done.returncode})")


def _artifacts() -> Path:
    from humancal.settings import state_dir

    return state_dir() / "artifacts"  # the IO managers' layout: <asset>/<partition>.parquet


def _stored(asset: str, partition: str) -> pd.DataFrame:
    path = _artifacts() / asset / f"{partition}.parquet"
    if not path.exists():
        raise SystemExit(f"{asset} of {partition} is not stored: run `humancal update --partition {partition}`")
    return pd.read_parquet(str(path))


def _register(source: str, work: Path) -> str:
    """The source's detections and true cameras written as a user's files and added as a calibrated capture."""
    dataset = source.split("__")[0]
    views = _stored("views", source).sort_values("view")
    folders = work / "openpose"
    _run("export", "detections", "--partition", source, "--format", "openpose", "--out", str(folders), "--overwrite")
    calib = work / "calib.toml"
    _run("export", "cameras", "--partition", source, "--ground-truth", "--format", "pose2sim", "--out", str(calib),
         "--overwrite")
    name = f"calmode_{dataset}"
    from humancal.datasets.sequences import load_datasets_config

    if f"{name}__capture" in load_datasets_config():
        _run("remove", name)
    sizes = [f"{w}x{h}" for w, h in zip(views["width_px"], views["height_px"])]
    _run("add", name, "--openpose", *[str(folders / f"view_{v:02d}") for v in views["view"]], "--image-size", *sizes,
         "--skeleton", "body25", "--cameras", str(calib))
    return f"{name}__capture"


def _score(source: str, capture: str) -> pd.DataFrame:
    """The capture's skeletons and bodies against the source's ground truth (the source's protocol)."""
    from evaluation.body_metrics import pipeline_body_table
    from humancal.body import BodyModel
    from humancal.camera import cameras_from_table
    from humancal.datasets.inputs import sequence_fps
    from humancal.datasets.sequences import load_datasets_config

    raw_source, raw_capture = _stored("raw_detections", source), _stored("raw_detections", capture)
    keys = ["frame", "view", "det_id", "joint"]
    merged = raw_source.merge(raw_capture, on=keys, suffixes=("", "_capture"))
    if len(merged) != len(raw_source) or (merged[["x_px", "y_px"]].to_numpy()
                                          - merged[["x_px_capture", "y_px_capture"]].to_numpy()).__abs__().max() > 1e-3:
        raise SystemExit("the capture's detections are not the source's, detection for detection")
    spec = load_datasets_config()[source]
    cameras = cameras_from_table(_stored("gt_cameras", source))
    return pipeline_body_table(
        spec, body=BodyModel(), regime="fixed", fps=sequence_fps(spec)[0],
        fitted_motions=_stored("fitted_motions", capture),
        refined_cameras=cameras_from_table(_stored("refined_cameras", capture)), fit_seconds=float("nan"),
        associations=_stored("associations", capture), skeletons3d=_stored("skeletons3d", capture),
        lifted_detections=_stored("detections", capture), detections=raw_source,
        cameras=cameras_from_table(_stored("extrinsics", capture)), gt_associations=_stored("gt_associations", source),
        gt_poses3d=_stored("gt_poses3d", source), gt_cameras=cameras, gt_motions=_stored("gt_motions", source))


def _headline(table: pd.DataFrame, label: str) -> pd.DataFrame:
    rows = table[table["view"].isna() & table["metric"].isin(METRICS)] if "view" in table else \
        table[table["metric"].isin(METRICS)]
    return rows.pivot_table(index="method", columns="metric", values="value").assign(source=label)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--partition", required=True, help="a partition with ground truth, e.g. synthetic__demo")
    parser.add_argument("--work", type=Path, default=None, help="folder for the capture's files")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="calmode_"))
    capture = _register(args.partition, work)
    _run("update", "--partition", capture)
    scored = _score(args.partition, capture)
    # with every camera held, the fit's rows are named "init" (evaluation.body_metrics.PIPELINE_METHOD["fixed"])
    scored = scored[scored["method"].isin(["skeletons3d", "init"])].replace({"method": {
        "skeletons3d": "skeletons3d (capture, --cameras)", "init": "fitted bodies (capture, --cameras)"}})
    parts = [_headline(scored, capture), _headline(_stored("metric_tables", args.partition), args.partition)]
    benchmark = _artifacts() / "method_tables" / f"{args.partition}.parquet"
    if benchmark.exists():
        parts.append(_headline(pd.read_parquet(benchmark), f"{args.partition} (humancal benchmark)"))
    table = pd.concat(parts)
    keep = table.index.str.contains("capture") | table.index.isin(["skeletons3d_gt_cameras", "gt_cameras",
                                                                   "skeletons3d", "int_ext"])
    print(table[keep].to_markdown(floatfmt=".2f"))


if __name__ == "__main__":
    main()
