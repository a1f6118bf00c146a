"""``humancal benchmark``: the paper's regimes fitted on chosen partitions (``method_tables``, on request), then the
benchmark and timing tables, then the side-by-side report.

    humancal benchmark --partition shelf__test [--methods ext,gt_cameras,separate]

Each partition is first brought up to date as ``humancal update`` would (so the pipeline's own fit and metric
table are current), then its ``method_tables`` is materialized, then the unpartitioned ``benchmark_table`` and
``stage_timings``, and ``humancal report --benchmark`` prints the result.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

__all__ = ["add_parser"]


def add_parser(sub: argparse._SubParsersAction, cmd_update: Callable, instance: Callable, run_config: dict) -> None:
    """Register ``humancal benchmark`` (``cmd_update``, ``instance`` and ``run_config`` come from the CLI)."""
    p = sub.add_parser("benchmark", help="fit the paper's regimes on partitions (method_tables), then the "
                                         "benchmark and timing tables, and print them beside the paper's numbers")
    p.add_argument("--partition", action="append", required=True, help="partition (repeatable), e.g. shelf__test")
    p.add_argument("--methods", default=None,
                   help="comma-separated methods of method_tables (default: every one but int_ext, which the "
                        "pipeline's own fit gives; see docs/refinement.md)")
    p.set_defaults(func=lambda args: run_benchmark(args, cmd_update, instance, run_config))


def run_benchmark(args, cmd_update: Callable, instance_of: Callable, run_config: dict) -> int:
    import dagster as dg

    from evaluation.method_comparison import METHODS
    from pipelines.cli.benchmark_report import report_benchmark
    from pipelines.definitions import defs
    from pipelines.run_guard import run_tags

    methods = args.methods.split(",") if args.methods else None
    unknown = sorted(set(methods or ()) - set(METHODS))
    if unknown:
        raise SystemExit(f"humancal: unknown method(s) {unknown}; known: {', '.join(METHODS)}")
    status = cmd_update(argparse.Namespace(partition=args.partition))
    if status:
        print("humancal: the update failed; no benchmark fits", file=sys.stderr)
        return status
    instance = instance_of()
    from pipelines.quiet_warp import init_warp_quietly

    init_warp_quietly()  # the fits build the body model: no CUDA-driver warning from warp on a CPU-only machine
    ops = dict(run_config)
    if methods:
        ops = {**ops, "ops": {"method_tables": {"config": {"methods": methods}}}}
    for partition in args.partition:
        print(f"method_tables[{partition}]: fitting {', '.join(methods or ['every regime'])} ...", flush=True)
        result = dg.materialize(assets=list(defs.assets), resources=defs.resources,
                                selection=dg.AssetSelection.assets("method_tables"), partition_key=partition,
                                instance=instance, run_config=ops, tags=run_tags(), raise_on_error=False)
        if not result.success:
            print(f"humancal: method_tables[{partition}] failed (see the log above)", file=sys.stderr)
            return 1
    result = dg.materialize(assets=list(defs.assets), resources=defs.resources,
                            selection=dg.AssetSelection.assets("benchmark_table", "stage_timings"),
                            instance=instance, run_config=run_config, tags=run_tags(), raise_on_error=False)
    if not result.success:
        print("humancal: benchmark_table / stage_timings failed (see the log above)", file=sys.stderr)
        return 1
    return report_benchmark(argparse.Namespace(partition=args.partition, format="md"), instance_of)
