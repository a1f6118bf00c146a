"""Per-stage timing table: the wall seconds of every per-sequence asset's latest materialization, from the run
history of the Dagster instance (the step's start and end in its run's step stats).

A multi-asset (``sequence_inputs``, ``association``, ``body_fit``) computes its assets in one step: each of them
shows that step's seconds, and the ``total`` row counts each step once. ``total`` is the method's path from
``detections`` to ``metric_tables``: every asset on a path between the two (so neither the ground-truth inputs nor
the references computed from them, nor ``method_tables``), the latest materialization of each; it is NaN while one
of them has no recorded time.
"""


from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass

import dagster as dg
import numpy as np
import pandas as pd

from assets.common import UPDATE_CONDITION, table_metadata, table_output
from assets.partitions import SEQUENCES
from evaluation.benchmark import stage_timings_markdown
from evaluation.paper_results import paper_results
from humancal.tables.schemas import SCHEMAS, validate_table

__all__ = ["TimedGraph", "build_stage_timings_asset", "stage_timings_table", "timed_graph", "timed_partitions"]

PATH_START, PATH_END = "detections", "metric_tables"
TOTAL = "total"
GROUP = "benchmark_summary"
"""The group of the unpartitioned benchmark assets (``method_tables``, partitioned, is in group ``benchmark``: a
selection must not mix partitioned and unpartitioned assets)."""


@dataclass(frozen=True)
class TimedGraph:
    """What the timing table covers.

    Attributes:
        assets: the per-sequence assets (partitioned by sequence: group ``sequence`` and ``method_tables``),
            upstream first.
        path: those on a path from ``detections`` to ``metric_tables`` (both included): the ``total``.
    """

    assets: tuple[str, ...]
    path: frozenset[str]


def timed_graph(specs: Iterable[dg.AssetSpec]) -> TimedGraph:
    """The per-sequence assets of ``specs`` (e.g. ``defs.resolve_all_asset_specs()``) and the method's path."""
    specs = [spec for spec in specs if spec.partitions_def == SEQUENCES]
    names = {spec.key.to_user_string() for spec in specs}
    parents = {spec.key.to_user_string(): sorted(d.asset_key.to_user_string() for d in spec.deps
                                                 if d.asset_key.to_user_string() in names) for spec in specs}
    children: dict[str, list[str]] = defaultdict(list)
    for name, ups in parents.items():
        for up in ups:
            children[up].append(name)
    order, placed = [], set()
    while len(order) < len(parents):  # upstream first, ties by name (the graph is acyclic)
        ready = sorted(n for n in parents if n not in placed and all(p in placed for p in parents[n]))
        order.extend(ready)
        placed.update(ready)
    below = _closure([PATH_START], children) if PATH_START in names else set()
    above = _closure([PATH_END], parents) if PATH_END in names else set()
    return TimedGraph(tuple(order), frozenset(below & above))


def _closure(start: list[str], edges: dict[str, list[str]]) -> set[str]:
    out, todo = set(), list(start)
    while todo:
        name = todo.pop()
        if name not in out:
            out.add(name)
            todo.extend(edges.get(name, ()))
    return out


def timed_partitions(instance: dg.DagsterInstance) -> list[str]:
    """The registered partitions with a materialized ``metric_tables``."""
    registered = set(instance.get_dynamic_partitions(SEQUENCES.name))
    return sorted(registered & set(instance.get_materialized_partitions(dg.AssetKey(PATH_END))))


def stage_timings_table(instance: dg.DagsterInstance, graph: TimedGraph,
                        partitions: Iterable[str] | None = None) -> pd.DataFrame:
    """The ``stage_timings`` table of ``partitions`` (default: :func:`timed_partitions`): per partition, one row per
    materialized asset of ``graph`` and the ``total`` of the method's path."""
    rows = []
    step_stats: dict[str, dict] = {}
    for partition in partitions if partitions is not None else timed_partitions(instance):
        steps: dict[tuple[str, str], float] = {}
        complete = True
        for asset in graph.assets:
            records = instance.fetch_materializations(
                dg.AssetRecordsFilter(asset_key=dg.AssetKey(asset), asset_partitions=[partition]), limit=1).records
            if not records:
                complete &= asset not in graph.path
                continue
            record = records[0]
            step = record.event_log_entry.step_key or ""
            if record.run_id not in step_stats:
                step_stats[record.run_id] = {s.step_key: s for s in instance.get_run_step_stats(record.run_id)}
            stats = step_stats[record.run_id].get(step)
            seconds = (stats.end_time - stats.start_time
                       if stats is not None and stats.start_time is not None and stats.end_time is not None
                       else float("nan"))
            rows.append((partition, asset, step, seconds, record.run_id, record.timestamp))
            if asset in graph.path:
                steps[(record.run_id, step)] = seconds
                complete &= bool(np.isfinite(seconds))
        total = float(sum(steps.values())) if complete and steps else float("nan")
        rows.append((partition, TOTAL, "", total, None, None))
    table = pd.DataFrame(rows, columns=SCHEMAS["stage_timings"].names)
    table["materialized_at"] = pd.to_datetime(table["materialized_at"].astype(float), unit="s", utc=True).dt.floor("us")
    table = table.astype({"run_id": object})
    return validate_table(table, "stage_timings", source="stage_timings")


def build_stage_timings_asset(sequence_specs: Iterable[dg.AssetSpec]) -> dg.AssetsDefinition:
    """The unpartitioned ``stage_timings`` asset (group ``benchmark_summary``) over the per-sequence assets of
    ``sequence_specs``; it follows ``metric_tables`` (``humancal update`` computes it once every partition's metric
    table is up to date)."""
    graph = timed_graph(sequence_specs)
    deps = [PATH_END] if PATH_END in graph.assets else []

    @dg.asset(name="stage_timings", group_name=GROUP, deps=deps, metadata=table_metadata("stage_timings"),
              code_version="1", automation_condition=UPDATE_CONDITION)
    def stage_timings(context: dg.AssetExecutionContext) -> dg.Output:
        """Wall seconds of the latest materialization of every per-sequence asset, per sequence with a
        materialized ``metric_tables``, and their total from ``detections`` to ``metric_tables`` (asset ``total``):
        from the step stats of the runs that materialized them."""
        partitions = timed_partitions(context.instance)
        registered = sorted(context.instance.get_dynamic_partitions(SEQUENCES.name))
        left = [p for p in registered if p not in partitions]
        if left:
            context.log.info(f"skipped (no materialized metric_tables): {', '.join(left)}")
        table = stage_timings_table(context.instance, graph, partitions)
        totals = table[table["asset"] == TOTAL].set_index("sequence")["seconds"]
        context.log.info("total seconds from detections to metric_tables: " + (", ".join(
            f"{p} {s:.1f}" for p, s in totals.items()) or "none"))
        return table_output(table, "stage_timings", rows=len(table), partitions=", ".join(partitions) or "none",
                            skipped=", ".join(left) or "none",
                            summary=dg.MetadataValue.md(stage_timings_markdown(table, paper_results())))

    return stage_timings
