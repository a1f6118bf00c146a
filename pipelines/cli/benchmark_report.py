"""``humancal report --benchmark``: the benchmark side by side with the paper, and the per-stage timing table.

The benchmark is the stored ``benchmark_table`` when it is materialized (with a note when a per-partition table
stored later is not in it); otherwise it is built here from the stored ``metric_tables`` and ``method_tables``
of every partition, as the asset would build it, and the output says so. The timing table is read from the run
history of the instance (the same function as the ``stage_timings`` asset), so it is always current.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import pandas as pd
from upath import UPath

__all__ = ["report_benchmark"]

PER_PARTITION_TABLES = ("metric_tables", "method_tables")


def _stored_partition_tables(root: str, partitions: list[str] | None) -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """Every stored per-partition metrics table (of ``partitions`` only, when given) and the partitions of each."""
    from evaluation.benchmark import normalise_metrics

    tables, found = [], {}
    for asset in PER_PARTITION_TABLES:
        folder = UPath(root) / asset
        files = sorted(folder.glob("*.parquet")) if folder.exists() else []
        files = [f for f in files if partitions is None or f.stem in partitions]
        found[asset] = [f.stem for f in files]
        tables += [normalise_metrics(pd.read_parquet(str(f))) for f in files]
    if not tables:
        raise SystemExit("humancal: no metric tables stored yet; run `humancal demo` or `humancal update` first")
    return pd.concat(tables, ignore_index=True), found


def _newer_than(path: UPath, root: str) -> list[str]:
    """The stored per-partition tables written after ``path`` (``asset[partition]``); empty where unknown."""
    try:
        since = path.stat().st_mtime
        newer = []
        for asset in PER_PARTITION_TABLES:
            folder = UPath(root) / asset
            for f in sorted(folder.glob("*.parquet")) if folder.exists() else []:
                if f.stat().st_mtime > since:
                    newer.append(f"{asset}[{f.stem}]")
        return newer
    except (OSError, AttributeError, NotImplementedError):
        return []


def _only(table: pd.DataFrame, partitions: list[str] | None) -> pd.DataFrame:
    """``table`` with our rows restricted to ``partitions`` (the paper's rows, per dataset, stay)."""
    if not partitions:
        return table
    keys = table["dataset"].astype(str) + "__" + table["sequence"].astype(str)
    return table[table["sequence"].isna() | keys.isin(partitions)].reset_index(drop=True)


def benchmark_for_report(root: str, partitions: list[str] | None) -> tuple[pd.DataFrame, str]:
    """The benchmark table to report and a line saying where it comes from."""
    from evaluation.benchmark import benchmark_table
    from evaluation.paper_results import paper_results, peer_results
    from humancal.tables.schemas import SCHEMAS
    from resources.io_managers import partition_path

    stored = partition_path(root, "benchmark_table", None)
    if stored.exists():
        table = pd.read_parquet(str(stored))
        if list(table.columns) == SCHEMAS["benchmark"].names:
            newer = _newer_than(stored, root)
            note = f"benchmark_table as stored ({stored})"
            if newer:
                note += (f"; written before {', '.join(newer[:4])}{' ...' if len(newer) > 4 else ''}: "
                         "`humancal update` (or materializing benchmark_table) brings it up to date")
            return _only(table, partitions), note
    metrics, found = _stored_partition_tables(root, partitions)
    table = benchmark_table(metrics, paper_results(), peer_results())
    read = "; ".join(f"{asset}: {', '.join(parts)}" for asset, parts in found.items() if parts)
    return table, (f"benchmark_table is not materialized: built here from the stored per-partition tables ({read})")


def report_benchmark(args, instance: Callable[[], object]) -> int:
    """Print the benchmark (markdown, or the long table as CSV with ``--format csv``) and the timing table.

    Args:
        args: the parsed ``humancal report`` options (``partition``, ``format``).
        instance: gives the Dagster instance holding the run history.
    """
    from evaluation.benchmark import benchmark_markdown, stage_timings_markdown
    from evaluation.paper_results import paper_results
    from pipelines.definitions import artifacts_root

    table, source = benchmark_for_report(artifacts_root(), args.partition)
    print(f"humancal: {source}", file=sys.stderr)
    if source.startswith("benchmark_table as stored"):
        for line in left_out_lines(instance()):
            print(f"humancal: {line}", file=sys.stderr)
    if args.format == "csv":
        sys.stdout.write(table.to_csv(index=False))
        return 0
    sys.stdout.write(benchmark_markdown(table))
    sys.stdout.write("\n## Per-stage seconds (latest materialization of each asset, from the run history)\n\n")
    sys.stdout.write(stage_timings_markdown(_timings(instance(), args.partition), paper_results()))
    return 0


def left_out_lines(instance) -> list[str]:
    """The partitions the stored ``benchmark_table`` was computed without (failed, or held back by a failed blocking
    check), from its latest materialization's metadata."""
    import dagster as dg

    event = instance.get_latest_materialization_event(dg.AssetKey("benchmark_table"))
    left_out = event.asset_materialization.metadata.get("left_out") if event and event.asset_materialization else None
    text = getattr(left_out, "value", None) or getattr(left_out, "md_str", None) or ""
    parts = [line.removeprefix("- ") for line in str(text).splitlines() if line.startswith("- ")]
    return [f"benchmark_table left out {part}" for part in parts]


def _timings(instance, partitions: list[str] | None) -> pd.DataFrame:
    from assets.timings import stage_timings_table, timed_graph, timed_partitions
    from pipelines.definitions import defs

    graph = timed_graph(defs.resolve_all_asset_specs())
    chosen = [p for p in timed_partitions(instance) if not partitions or p in partitions]
    return stage_timings_table(instance, graph, chosen)
