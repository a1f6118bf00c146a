"""``humancal``: the command-line interface (the stable entry point for users and scripts).

    humancal demo [--all]                materialize what synthetic__demo needs (the lifter first), print its figures
    humancal update [--partition P ...]  materialize only what is missing or stale
    humancal report [--partition P] [--format md|csv]   (P may also be cmu_mocap__held_out_02_14)
    humancal report --benchmark [--partition P]   ours beside the paper's numbers, and the per-stage seconds
    humancal benchmark --partition P [--methods M,...]   fit the paper's regimes (method_tables), then report --benchmark
    humancal export detections|cameras --partition P --format F --out PATH
    humancal export motions --partition P --format bvh|gltf|npz|obj --out DIR [--frames A:B[:S]] [--fps F]
    humancal export overlays --partition P --format mp4 --out DIR [--videos PATH ...]   (docs/viewing.md)
    humancal export footage --partition P --format mp4 --out DIR   plain footage of a synthetic scene
    humancal view --partition P [--save FILE.rrd]   the result in 3D (Rerun)
    humancal train lifter [--discard]    train the lifter here (replaces the shipped weights), or go back to them
    humancal train prior [--variant V]   train a motion prior variant here and compute its held-out figures
    humancal add NAME --openpose DIR ... --image-size WxH   register your own capture (pipelines/cli/add.py)
    humancal remove NAME [--sequence SEQ]   forget a capture you added: config entry, partitions, artifacts
    humancal ui                          the Dagster UI on 127.0.0.1
    humancal worker                      a Celery worker for `update` on a cluster (docs/cluster.md)
    humancal -v COMMAND ...              (or COMMAND -v) also print what was left waiting and why

All commands share one persistent Dagster instance in ``<local dir>/dagster_home`` (telemetry off; the local dir is
the state dir unless that is on a store: ``humancal/settings.py``), so materializations and lineage survive between
commands and are visible in the UI.

This module imports only the standard library: the parser (``humancal --help``, argument errors) answers in a
fraction of a second, and each command imports what it needs (the commands live in ``pipelines/cli/<command>.py``).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import logging
import os
import signal
import sys
from pathlib import Path

from pipelines.instance import dagster_home, persistent_instance

DEMO_PARTITION = "synthetic__demo"
SHARED_METRIC_TABLES = {"cmu_mocap__held_out_02_14": "lifter_heldout_metrics"}
"""Metric tables of unpartitioned assets, by the name ``report --partition`` knows them under."""
QUIET_RUN_CONFIG = {"loggers": {"console": {"config": {"log_level": "INFO"}}}}
_instance = persistent_instance
"""The persistent instance (the name the command modules call through ``cli``, so that tests can replace it)."""


def register_partitions(instance, defs) -> list[str]:
    """Add every loadable sequence of the datasets config as a partition; returns all keys."""
    from pipelines.partitions import SEQUENCES

    keys = [spec.key for spec in defs.resources["datasets"].available()]
    existing = set(instance.get_dynamic_partitions(SEQUENCES.name))
    new = [k for k in keys if k not in existing]
    if new:
        instance.add_dynamic_partitions(SEQUENCES.name, new)
    return keys


def _check_partitions(requested: list[str] | None, defs) -> None:
    if not requested:
        return
    datasets = defs.resources["datasets"]
    available = {s.key for s in datasets.available()}
    for key in requested:
        spec = datasets.spec(key)  # raises for unknown dataset / sequence
        if spec.key not in available:
            raise SystemExit(
                f"humancal: partition {key} needs {spec.data_folder}/ under the data root (set HUMANCAL_DATA_DIR)"
            )


def _print_metrics(table, fmt: str) -> None:
    if fmt == "csv":
        sys.stdout.write(table.to_csv(index=False))
        return
    if "failed_checks" in table.columns:  # shown only where some figure comes from cameras that failed a check
        flags = table["failed_checks"].fillna("")
        table = table.assign(failed_checks=flags) if (flags != "").any() else table.drop(columns="failed_checks")
    if "view" in table.columns:  # per-view rows show their view, the others nothing (not "<NA>")
        table = table.assign(view=table["view"].astype("object").where(table["view"].notna(), ""))
    sys.stdout.write(table.to_markdown(index=False, floatfmt=".2f") + "\n")


def _stored_metrics(partitions: list[str] | None, headline_only: bool):
    import pandas as pd
    from upath import UPath

    from pipelines.definitions import artifacts_root
    from resources.io_managers import partition_path

    shared = {key: partition_path(artifacts_root(), asset, None) for key, asset in SHARED_METRIC_TABLES.items()}
    prior_folder = UPath(artifacts_root()) / "prior_metrics"  # one table per variant, same held-out partition
    prior_files = sorted(prior_folder.glob("*.parquet")) if prior_folder.exists() else []
    if partitions:
        files = [shared.get(p) or partition_path(artifacts_root(), "metric_tables", p) for p in partitions]
        missing = [p for p, f in zip(partitions, files) if not f.exists()]
        if missing:
            raise SystemExit(f"humancal: {_explain_missing_tables(missing)}")
        if "cmu_mocap__held_out_02_14" in partitions:
            files += prior_files
    else:
        folder = UPath(artifacts_root()) / "metric_tables"
        files = [f for f in shared.values() if f.exists()] + prior_files
        files += sorted(folder.glob("*.parquet")) if folder.exists() else []
    if not files:
        raise SystemExit("humancal: no metric tables stored yet; run `humancal demo` or `humancal update` first")
    table = pd.concat([pd.read_parquet(str(f)) for f in files], ignore_index=True)
    if "view" not in table.columns:  # stored before metric tables had a view column
        table.insert(table.columns.get_loc("metric") + 1, "view", pd.NA)
    table["view"] = table["view"].astype("Int32")
    if "failed_checks" not in table.columns:  # stored before metric tables named the cameras' failed checks
        table["failed_checks"] = None
    if headline_only:  # headline: not per view, no per-joint / per-group suffix
        table = table[table["view"].isna() & ~table["metric"].str.contains("/", regex=False)].drop(columns="view")
    return table


def _report_missing_data(defs, emit=print) -> dict:
    """The assets whose external data is missing here; prints them and what cannot be computed without them."""
    from pipelines.update import excluded_with_descendants

    exclude = _assets_missing_data(defs)
    for key, folder in exclude.items():
        emit(f"skipping {key.to_user_string()}: it needs {folder}/ under the data root (HUMANCAL_DATA_DIR)")
    downstream = sorted(k.to_user_string() for k in excluded_with_descendants(defs, exclude) - set(exclude))
    if downstream:
        emit(f"  ... and what depends on it: {', '.join(downstream)}")
    return exclude


def _assets_on_request(defs) -> list:
    """Assets that ``update`` never computes on its own (``lifter_trained``: ``humancal train lifter`` does)."""
    from assets.common import ON_REQUEST_KEY

    graph = defs.resolve_asset_graph()
    return [key for key in graph.materializable_asset_keys if (graph.get(key).metadata or {}).get(ON_REQUEST_KEY)]


def _print_active_lifter(emit=print) -> None:
    from pipelines.definitions import artifacts_root
    from resources.lifter_source import active_lifter

    emit(active_lifter(artifacts_root()).describe())


def _assets_missing_data(defs) -> dict:
    """Unpartitioned assets whose external data folder is not under the data root here."""
    from assets.common import REQUIRES_DATA_KEY

    root = defs.resources["datasets"].root()
    graph = defs.resolve_asset_graph()
    missing = {}
    for key in graph.materializable_asset_keys:
        folder = (graph.get(key).metadata or {}).get(REQUIRES_DATA_KEY)
        if folder and (root is None or not (root / folder).is_dir()):
            missing[key] = folder
    return missing


def _explain_missing_tables(missing: list[str]) -> str:
    """Why no table is stored: an unknown partition (named, with the known ones) or one never computed."""
    from pipelines.definitions import defs

    known = sorted({spec.key for spec in defs.resources["datasets"].available()} | set(SHARED_METRIC_TABLES))
    unknown = [p for p in missing if p not in known]
    if unknown:
        return f"unknown partition(s) {', '.join(unknown)}; known here: {', '.join(known)}"
    command = "humancal update" + "".join(f" --partition {p}" for p in missing if p not in SHARED_METRIC_TABLES)
    return f"no metric table stored yet for {', '.join(missing)}; run `{command}`"


def cmd_report(args) -> int:
    if args.benchmark:  # pipelines/cli/benchmark_report.py
        from pipelines.cli.benchmark_report import report_benchmark

        return report_benchmark(args, _instance)
    # Markdown is for reading: headline rows unless --all; CSV is for tools: every row.
    _print_metrics(_stored_metrics(args.partition, headline_only=args.format == "md" and not args.all), args.format)
    return 0


def cmd_ui(args) -> int:
    home = dagster_home()
    env = dict(os.environ, DAGSTER_HOME=str(home))
    repo = Path(__file__).resolve().parents[2]
    # The Dagster of this interpreter's environment, whether or not that environment is activated (a bare
    # `dagster` would be looked up on PATH, and may be missing or another installation).
    argv = [sys.executable, "-m", "dagster", "dev", "-w", "workspace.yaml", "-h", "127.0.0.1", "-p", str(args.port)]
    # A process started in the background by a non-interactive shell inherits SIGINT as ignored, and
    # dagster maps SIGTERM onto its SIGINT handler: restore the defaults so Ctrl-C and `kill` stop it.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.chdir(repo)
    os.execvpe(argv[0], argv, env)
    return 0  # not reached


def _command(module: str, name: str):
    """A command imported when it runs (``pipelines.cli.<module>.<name>``), so that the parser stays light."""
    def run(args):
        return getattr(importlib.import_module(f"pipelines.cli.{module}"), name)(args)

    return run


cmd_update = _command("update", "cmd_update")
cmd_demo = _command("update", "cmd_demo")
cmd_export = _command("export", "cmd_export")
cmd_train = _command("train", "cmd_train")
cmd_remove = _command("remove", "cmd_remove")

WRITES_STATE = {"demo", "update", "add", "remove", "train", "benchmark", "ui"}
"""Commands that write the state dir (checked to be writable before they start)."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="humancal", description="Cameras and body meshes from people in multi-view video.")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="also print what was left waiting and why, and the INFO log of the runs")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help=f"materialize the whole graph for {DEMO_PARTITION} and print its headline figures")
    p.add_argument("--all", action="store_true", help="print every headline row of the metric table instead")
    p.set_defaults(func=cmd_demo)
    p = sub.add_parser("update", help="materialize only missing or stale asset partitions")
    p.add_argument("--partition", action="append", help="restrict to this partition (repeatable), e.g. synthetic__demo")
    p.set_defaults(func=cmd_update)
    p = sub.add_parser("report", help="print stored metric tables")
    p.add_argument("--partition", action="append", help="only this partition (repeatable)")
    p.add_argument("--format", choices=("md", "csv"), default="md")
    p.add_argument("--all", action="store_true", help="md: include per-joint / per-view rows (csv always has them)")
    p.add_argument("--benchmark", action="store_true",
                   help="ours beside the paper's numbers (benchmark_table) and the per-stage seconds")
    p.set_defaults(func=cmd_report)
    _add_export_parser(sub)
    p = sub.add_parser("train", help="train a model here on the data root's mocap (it then replaces the shipped one)")
    p.add_argument("model", choices=("lifter", "prior"))
    p.add_argument("--variant", help="prior: the variant to train (default motion_prior; see docs/motion_prior.md)")
    p.add_argument("--seed", type=int, help="training seed (default: the shipped configuration's)")
    p.add_argument("--epochs", type=int, help="training epochs (default: the shipped configuration's)")
    p.add_argument("--discard", action="store_true", help="delete the trained model: the shipped one is in force again")
    p.set_defaults(func=cmd_train)
    from pipelines.cli.add import add_parser as add_capture_command  # humancal add NAME --openpose ...
    add_capture_command(sub)
    p = sub.add_parser("remove", help="forget a capture you added (humancal add): its datasets entry, its "
                                      "partitions and their artifacts")
    p.add_argument("name", help="the dataset name given to `humancal add` (the first half of the partition key)")
    p.add_argument("--sequence", help="remove this sequence only (default: every sequence of the dataset)")
    p.set_defaults(func=cmd_remove)
    from pipelines.cli.benchmark import add_parser as add_benchmark_command  # humancal benchmark --partition P
    add_benchmark_command(sub, cmd_update, _instance, QUIET_RUN_CONFIG)
    from pipelines.cli.view import add_parser as add_view_command  # humancal view --partition P [--save F]
    add_view_command(sub)
    from pipelines.cli.worker import add_parser as add_worker_command  # humancal worker [--concurrency N]
    add_worker_command(sub)
    p = sub.add_parser("ui", help="start the Dagster UI (dagster dev) on 127.0.0.1")
    p.add_argument("--port", type=int, default=3000)
    p.set_defaults(func=cmd_ui)
    for command in sub.choices.values():  # `humancal update -v` as well as `humancal -v update`
        command.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                             help="also print what was left waiting and why")
    return parser


def _add_export_parser(sub) -> None:
    from pipelines.cli.format_names import CAMERA_FORMATS, MOTION_FORMATS

    p = sub.add_parser("export", help="write stored detections, cameras or fitted motions in another tool's format")
    p.add_argument("what", choices=("detections", "cameras", "motions", "overlays", "footage"))
    p.add_argument("--partition", required=True)
    p.add_argument("--format", required=True,
                   help=f"openpose (detections); {', '.join(CAMERA_FORMATS)} (cameras); {', '.join(MOTION_FORMATS)} "
                        "(motions; see docs/formats.md); mp4 (overlays: one video per view and a contact sheet; "
                        "footage: a synthetic scene's people as silhouettes, one video per view)")
    p.add_argument("--out", required=True, help="output folder (detections, motions, easymocap, colmap) or file")
    p.add_argument("--frames", default=None,
                   help="motions (obj only) and overlays: START:STOP[:STEP] sequence frame numbers to write "
                        "(STOP excluded)")
    p.add_argument("--fps", type=float, default=None,
                   help="motions: frame rate of the sequence (default: the dataset's, else 30)")
    p.add_argument("--cameras-asset", default=None,
                   help="which stored cameras table to export: final_cameras (default: the refined cameras when "
                        "the refinement passed its check, else the calibrated ones), extrinsics, refined_cameras")
    p.add_argument("--ground-truth", action="store_true",
                   help="export the dataset's ground-truth cameras (gt_cameras) instead of the estimated ones")
    p.add_argument("--videos", nargs="+", metavar="PATH", default=None,
                   help="overlays: draw on this footage, one video file or image folder per view, or one folder "
                        "holding <view>.mp4 per view (default: the footage given to `humancal add --videos`)")
    p.add_argument("--no-detections", action="store_true",
                   help="overlays: draw the reprojected fit only, not the detections")
    p.add_argument("--overwrite", action="store_true",
                   help="replace what is at --out (without it an existing file or non-empty folder is an error)")
    p.set_defaults(func=cmd_export)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.INFO if args.verbose else logging.WARNING
    logging.basicConfig(level=level, format="%(asctime)s %(name)s: %(message)s", datefmt="%H:%M:%S")
    logging.getLogger("alembic").setLevel(logging.WARNING)  # Dagster's storage migrations
    try:
        if args.command in WRITES_STATE:
            from pipelines.cli.state_access import require_writable_state

            require_writable_state()
        return args.func(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"humancal: error: {err}", file=sys.stderr)
        return 2
    except PermissionError as err:  # a read-only state dir or output folder found while writing
        from pipelines.cli.state_access import permission_message

        print(permission_message(err), file=sys.stderr)
        return 2
    finally:
        if argv is None:  # the `humancal` process itself, about to exit (tests pass argv and go on)
            # Freezing what is allocated spares the interpreter's final garbage collection of hundreds of
            # thousands of objects: about 0.4 s at exit once Dagster and torch are imported.
            gc.freeze()

