"""``humancal``: the command-line interface (the stable entry point for users and scripts).

    humancal demo                        materialize what synthetic__demo needs (the lifter first), print its metrics
    humancal update [--partition P ...]  materialize only what is missing or stale
    humancal report [--partition P] [--format md|csv]   (P may also be cmu_mocap__held_out_02_14)
    humancal report --benchmark [--partition P]   ours beside the paper's numbers, and the per-stage seconds
    humancal benchmark --partition P [--methods M,...]   fit the paper's regimes (method_tables), then report --benchmark
    humancal export detections|cameras --partition P --format F --out PATH
    humancal export motions --partition P --format bvh|gltf|npz|obj --out DIR [--frames A:B[:S]] [--fps F]
    humancal train lifter [--discard]    train the lifter here (replaces the shipped weights), or go back to them
    humancal train prior [--variant V]   train a motion prior variant here and compute its held-out figures
    humancal add NAME --openpose DIR ... --image-size WxH   register your own capture (pipelines/capture_cli.py)
    humancal ui                          the Dagster UI on 127.0.0.1

All commands share one persistent Dagster instance in ``<state dir>/dagster_home`` (telemetry off),
so materializations and lineage survive between commands and are visible in the UI.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import time
from pathlib import Path

DEMO_PARTITION = "synthetic__demo"
SHARED_METRIC_TABLES = {"cmu_mocap__held_out_02_14": "lifter_heldout_metrics"}
"""Metric tables of unpartitioned assets, by the name ``report --partition`` knows them under."""
QUIET_RUN_CONFIG = {"loggers": {"console": {"config": {"log_level": "INFO"}}}}


def dagster_home() -> Path:
    """The persistent DAGSTER_HOME of this checkout (created with telemetry disabled)."""
    from humancal.settings import state_dir

    home = state_dir() / "dagster_home"
    home.mkdir(parents=True, exist_ok=True)
    config = home / "dagster.yaml"
    if not config.exists():
        config.write_text("telemetry:\n  enabled: false\n")
    return home


def _instance():
    os.environ["DAGSTER_HOME"] = str(dagster_home())
    import dagster as dg

    return dg.DagsterInstance.get()


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


def cmd_demo(args) -> int:
    from pipelines.definitions import defs
    from pipelines.update import update

    instance = _instance()
    register_partitions(instance, defs)
    print(f"humancal demo: materializing what {DEMO_PARTITION} needs (the first run builds the body model's cache, "
          "about a minute; later runs reuse it) ...", flush=True)
    _print_active_lifter()
    t0 = time.perf_counter()
    exclude = [*_report_missing_data(defs), *_assets_on_request(defs)]
    result = update(defs, instance, partitions=[DEMO_PARTITION], exclude=exclude, on_round=_print_round,
                    run_config=QUIET_RUN_CONFIG)
    print(f"materialized {result.count} asset partitions in {time.perf_counter() - t0:.1f} s\n", flush=True)
    if _report_failures(result):
        # Not the stored table: it was computed by an earlier run, from other cameras, and would read as if all
        # were fine.
        if result.blocking_failed:
            print(f"no metric table: a blocking check failed, so metric_tables[{DEMO_PARTITION}] was not computed "
                  "from these cameras (a table stored by an earlier run describes other ones: `humancal report`)",
                  file=sys.stderr)
        return 1
    _print_metrics(_stored_metrics([DEMO_PARTITION], headline_only=True), "md")
    return 0


def _print_round(n, items) -> None:
    names = ", ".join(f"{k.to_user_string()}[{p}]" if p else k.to_user_string() for k, p in items)
    print(f"round {n}: {len(items)} stale or missing: {names}", flush=True)


def _report_missing_data(defs) -> dict:
    """The assets whose external data is missing here; prints them and what cannot be computed without them."""
    from pipelines.update import excluded_with_descendants

    exclude = _assets_missing_data(defs)
    for key, folder in exclude.items():
        print(f"skipping {key.to_user_string()}: it needs {folder}/ under the data root (HUMANCAL_DATA_DIR)")
    downstream = sorted(k.to_user_string() for k in excluded_with_descendants(defs, exclude) - set(exclude))
    if downstream:
        print(f"  ... and what depends on it: {', '.join(downstream)}")
    return exclude


def _assets_on_request(defs) -> list:
    """Assets that ``update`` never computes on its own (``lifter_trained``: ``humancal train lifter`` does)."""
    from assets.common import ON_REQUEST_KEY

    graph = defs.resolve_asset_graph()
    return [key for key in graph.materializable_asset_keys if (graph.get(key).metadata or {}).get(ON_REQUEST_KEY)]


def _print_active_lifter() -> None:
    from pipelines.definitions import artifacts_root
    from resources.lifter_source import active_lifter

    print(active_lifter(artifacts_root()).describe(), flush=True)


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


def cmd_update(args) -> int:
    from pipelines.definitions import defs
    from pipelines.update import update

    instance = _instance()
    register_partitions(instance, defs)
    _check_partitions(args.partition, defs)

    _print_active_lifter()
    exclude = [*_report_missing_data(defs), *_assets_on_request(defs)]
    result = update(defs, instance, partitions=args.partition or None, exclude=exclude,
                    on_round=_print_round, run_config=QUIET_RUN_CONFIG)
    print(f"materialized {result.count} asset partitions")
    return _report_failures(result)


def _report_failures(result) -> int:
    """Print what was left, what failed and every failed check; 1 if an asset partition or a blocking check failed."""
    for line in result.waiting_lines():  # left because an input cannot be brought up to date here
        print(line)
    _print_failed_checks(result)
    if result.failed:
        print(f"{len(result.failed)} asset partition(s) failed (what depends on them was left out):", file=sys.stderr)
        for asset, partition, message in result.failed:
            print(f"  {asset}[{partition}]: {message}" if partition else f"  {asset}: {message}", file=sys.stderr)
    return 1 if result.failed or result.blocking_failed else 0


def _print_failed_checks(result) -> None:
    """ERROR: a blocking check failed (what depends on it was not computed); WARN: a warning; ERROR (not
    blocking): a failed check that does not protect anything downstream."""
    if not result.checks:
        return
    blocking = sum(outcome.blocks for outcome in result.checks)
    print(f"{len(result.checks)} check(s) failed, {blocking} blocking:", file=sys.stderr)
    for outcome in result.checks:
        label = "ERROR" if outcome.blocks else "WARN" if outcome.severity == "WARN" else "ERROR (not blocking)"
        when = " (evaluated by an earlier run)" if outcome in result.earlier_checks else ""
        print(f"  {label} {outcome.where} {outcome.check}{when}: {outcome.description}", file=sys.stderr)


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
    if args.benchmark:  # pipelines/benchmark_report.py
        from pipelines.benchmark_report import report_benchmark

        return report_benchmark(args, _instance)
    # Markdown is for reading: headline rows unless --all; CSV is for tools: every row.
    _print_metrics(_stored_metrics(args.partition, headline_only=args.format == "md" and not args.all), args.format)
    return 0


def _stored_table(asset: str, partition: str):
    import pandas as pd

    from pipelines.definitions import artifacts_root
    from resources.io_managers import partition_path

    path = partition_path(artifacts_root(), asset, partition)
    if not path.exists():
        raise SystemExit(f"humancal: {asset} of {partition} is not stored ({path}); run `humancal update --partition {partition}`")
    return pd.read_parquet(str(path))


def cmd_export(args) -> int:
    """Hand detections or cameras of a partition to other tools (OpenPose JSON; Pose2Sim, anipose,
    EasyMocap, COLMAP, Shelf or humancal camera files)."""
    from humancal.camera import cameras_from_table
    from humancal.formats import write_cameras, write_openpose

    if args.what == "motions":
        from pipelines.motions_export import export_stored_motions

        return export_stored_motions(args, lambda: _stored_table("fitted_motions", args.partition))
    if args.what == "detections":
        if args.format != "openpose":
            raise SystemExit("humancal: detections export supports --format openpose")
        folders = write_openpose(_stored_table("raw_detections", args.partition), args.out, overwrite=args.overwrite)
        print(f"wrote OpenPose JSON for {len(folders)} views under {args.out}")
    else:
        asset = _cameras_asset(args)
        cameras = cameras_from_table(_stored_table(asset, args.partition))
        path = write_cameras(cameras, args.out, args.format)
        what = CAMERA_ASSETS.get(asset, "stored")
        print(f"wrote {len(cameras)} {what} cameras (asset {asset}, format {args.format}) to {path}")
    return 0


def cmd_train(args) -> int:
    """Train the lifter on the CMU mocap under the data root; from then on it replaces the shipped weights."""
    import dagster as dg

    if args.model == "prior":
        return _train_prior(args)

    from humancal.lifter import LifterConfig
    from pipelines.definitions import artifacts_root, build_definitions
    from resources.lifter_source import trained_lifter_path

    trained = trained_lifter_path(artifacts_root())
    if args.discard:
        if trained.exists():
            trained.unlink()
            print(f"deleted {trained}: the shipped lifter is in force again; `humancal update` re-lifts with it")
        else:
            print("no trained lifter stored: the shipped lifter is already in force")
        _print_active_lifter()
        return 0
    overrides = {k: v for k, v in (("seed", args.seed), ("epochs", args.epochs)) if v is not None}
    config = LifterConfig.default().replace(**overrides)
    defs = build_definitions(lifter_config=config)
    instance = _instance()
    missing = _assets_missing_data(defs)
    if dg.AssetKey("mocap_clips") in missing:
        raise SystemExit(f"humancal: training the lifter needs {missing[dg.AssetKey('mocap_clips')]}/ under the data "
                         "root (set HUMANCAL_DATA_DIR); the shipped lifter stays in force")
    selection = [dg.AssetKey("lifter_trained")]
    if instance.get_latest_materialization_event(dg.AssetKey("mocap_clips")) is None:
        selection.insert(0, dg.AssetKey("mocap_clips"))
    print(f"training the lifter ({config.epochs} epochs of {config.samples_per_epoch} samples, seed {config.seed}; "
          "about 15 minutes on 2 cores" + (", after retargeting the CMU mocap" if len(selection) == 2 else "") + ") ...",
          flush=True)
    result = dg.materialize(assets=list(defs.assets), resources=defs.resources,
                            selection=dg.AssetSelection.assets(*selection), instance=instance,
                            run_config=QUIET_RUN_CONFIG, raise_on_error=False)
    if not result.success:
        print("humancal: training failed; the lifter in force is unchanged (see the log above)", file=sys.stderr)
        return 1
    _print_active_lifter()
    print("`humancal update` now re-lifts every sequence with it (`humancal train lifter --discard` goes back to "
          "the shipped weights)")
    return 0


def _train_prior(args) -> int:
    """Train one variant of the motion prior (partition of ``motion_prior_checkpoint``) and compute its held-out
    figures (``prior_metrics``), retargeting the mocap first if it never was."""
    import dagster as dg

    from humancal.prior import PRIOR_VARIANTS, PriorConfig
    from pipelines.definitions import build_definitions

    if args.discard:
        raise SystemExit("humancal: --discard applies to the lifter only (the trained prior is an artifact of the graph)")
    variant = args.variant or "motion_prior"
    overrides = {k: v for k, v in (("seed", args.seed), ("epochs", args.epochs)) if v is not None}
    configs = {v: PriorConfig.default(v).replace(**overrides) if v == variant else PriorConfig.default(v)
               for v in PRIOR_VARIANTS}
    defs = build_definitions(prior_configs=configs)
    instance = _instance()
    missing = _assets_missing_data(defs)
    if dg.AssetKey("mocap_clips") in missing:
        raise SystemExit(f"humancal: training the motion prior needs {missing[dg.AssetKey('mocap_clips')]}/ under the "
                         "data root (set HUMANCAL_DATA_DIR)")
    selection = [dg.AssetKey("motion_prior_checkpoint"), dg.AssetKey("prior_metrics")]
    if instance.get_latest_materialization_event(dg.AssetKey("mocap_clips")) is None:
        selection.insert(0, dg.AssetKey("mocap_clips"))
    config = configs[variant]
    print(f"training the motion prior '{variant}' ({config.epochs} epochs of {config.steps_per_epoch} steps, seed "
          f"{config.seed}" + (", after retargeting the CMU mocap" if len(selection) == 3 else "") + "), then its "
          "held-out figures ...", flush=True)
    result = dg.materialize(assets=list(defs.assets), resources=defs.resources, partition_key=variant,
                            selection=dg.AssetSelection.assets(*selection), instance=instance,
                            run_config=QUIET_RUN_CONFIG, raise_on_error=False)
    if not result.success:
        print("humancal: training the motion prior failed (see the log above)", file=sys.stderr)
        return 1
    print("`humancal report --partition cmu_mocap__held_out_02_14` shows its figures")
    return 0


CAMERA_ASSETS = {"extrinsics": "estimated", "gt_cameras": "ground-truth"}
"""Stored camera tables ``export cameras`` knows by what they are; ``extrinsics`` is the default."""


def _cameras_asset(args) -> str:
    """The estimated cameras unless the ground truth (or another stored cameras table) is asked for by name."""
    if args.ground_truth and args.cameras_asset not in (None, "gt_cameras"):
        raise SystemExit(f"humancal: --ground-truth and --cameras-asset {args.cameras_asset} contradict each other")
    if args.ground_truth:
        return "gt_cameras"
    return args.cameras_asset or "extrinsics"


def cmd_ui(args) -> int:
    home = dagster_home()
    env = dict(os.environ, DAGSTER_HOME=str(home))
    repo = Path(__file__).resolve().parent.parent
    # The Dagster of this interpreter's environment, whether or not that environment is activated (a bare
    # `dagster` would be looked up on PATH, and may be missing or another installation).
    argv = [sys.executable, "-m", "dagster", "dev", "-m", "pipelines.definitions", "-h", "127.0.0.1", "-p", str(args.port)]
    # A process started in the background by a non-interactive shell inherits SIGINT as ignored, and
    # dagster maps SIGTERM onto its SIGINT handler: restore the defaults so Ctrl-C and `kill` stop it.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.chdir(repo)
    os.execvpe(argv[0], argv, env)
    return 0  # not reached


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="humancal", description="Cameras and body meshes from people in multi-view video.")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("demo", help=f"materialize the whole graph for {DEMO_PARTITION} and print its metrics").set_defaults(func=cmd_demo)
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
    p = sub.add_parser("export", help="write stored detections, cameras or fitted motions in another tool's format")
    p.add_argument("what", choices=("detections", "cameras", "motions"))
    p.add_argument("--partition", required=True)
    p.add_argument("--format", required=True,
                   help="openpose (detections); humancal, shelf, pose2sim, anipose, easymocap, colmap (cameras); "
                        "bvh, gltf, npz, obj (motions; see docs/formats.md)")
    p.add_argument("--out", required=True, help="output folder (detections, motions, easymocap, colmap) or file")
    p.add_argument("--frames", default=None,
                   help="motions, obj only: START:STOP[:STEP] sequence frame numbers to write (STOP excluded)")
    p.add_argument("--fps", type=float, default=None,
                   help="motions: frame rate of the sequence (default: the dataset's, else 30)")
    p.add_argument("--cameras-asset", default=None,
                   help="which stored cameras table to export (default: extrinsics, the estimated cameras)")
    p.add_argument("--ground-truth", action="store_true",
                   help="export the dataset's ground-truth cameras (gt_cameras) instead of the estimated ones")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_export)
    p = sub.add_parser("train", help="train a model here on the data root's mocap (it then replaces the shipped one)")
    p.add_argument("model", choices=("lifter", "prior"))
    p.add_argument("--variant", help="prior: the variant to train (default motion_prior; see docs/motion_prior.md)")
    p.add_argument("--seed", type=int, help="training seed (default: the shipped configuration's)")
    p.add_argument("--epochs", type=int, help="training epochs (default: the shipped configuration's)")
    p.add_argument("--discard", action="store_true", help="delete the trained model: the shipped one is in force again")
    p.set_defaults(func=cmd_train)
    from pipelines.capture_cli import add_parser as add_capture_command  # humancal add NAME --openpose ...
    add_capture_command(sub)
    from pipelines.benchmark_command import add_parser as add_benchmark_command  # humancal benchmark --partition P
    add_benchmark_command(sub, cmd_update, _instance, QUIET_RUN_CONFIG)
    p = sub.add_parser("ui", help="start the Dagster UI (dagster dev) on 127.0.0.1")
    p.add_argument("--port", type=int, default=3000)
    p.set_defaults(func=cmd_ui)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", datefmt="%H:%M:%S")
    logging.getLogger("alembic").setLevel(logging.WARNING)  # Dagster's storage migrations
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"humancal: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
