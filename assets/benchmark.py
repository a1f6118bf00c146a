"""Unpartitioned benchmark assets (group ``benchmark_summary``): every sequence's figures beside the paper's, and the
per-stage timing table.

``benchmark_table`` takes the per-sequence ``metric_tables`` and ``method_tables`` as inputs of every registered
partition (``AllPartitionMapping``; a partition without a stored table is skipped, named in the log), adds the
paper's numbers and the peer figures measured here (``evaluation/paper_results.py``) and stores the long table
(canonical table ``benchmark``) with its side-by-side markdown as metadata (``evaluation/benchmark.py``).

``humancal update`` computes it once every registered partition of ``metric_tables`` is up to date, never from a
partial set of partitions that could still be brought up to date. ``method_tables`` is computed on request only
(``humancal benchmark``): the update never waits for it and reads what is stored; a new one makes the benchmark
stale through its data version like any input. Partitions that failed, or that a failed blocking check holds back,
are left out instead of making it wait for ever: the update passes them with the reason as run config
(``left_out``), the asset drops their tables (a stored one would be out of date) and says which it left out and why
(log, metadata ``left_out``; ``humancal report --benchmark`` prints it).
``dagster asset materialize --select benchmark_table`` computes it from whatever is stored.
"""


import hashlib
from collections.abc import Sequence

import dagster as dg
import pandas as pd

from assets.common import UPDATE_CONDITION, table_metadata, table_output
from assets.partitions import SEQUENCES
from assets.timings import GROUP, build_stage_timings_asset
from evaluation.benchmark import benchmark_markdown, benchmark_table, normalise_metrics
from evaluation.paper_results import PAPER_FILE, PEER_FILE, paper_results, peer_results

__all__ = ["BENCHMARK_INPUTS", "FAN_IN_CONFIG_KEY", "BenchmarkConfig", "build_benchmark_assets"]

FAN_IN_CONFIG_KEY = "humancal/left_out_config"
"""Asset metadata of a fan-in asset (unpartitioned, reading every partition of a partitioned one) that takes the
partitions to leave out as run config (``{"left_out": {partition: reason}}``; ``humancal update`` sets it)."""

BENCHMARK_INPUTS = ("metric_tables", "method_tables")
"""The per-sequence ``metrics`` tables the benchmark reads, in this order (a figure in both keeps the later)."""

_DATA_DIGEST = hashlib.sha256(PAPER_FILE.read_bytes() + PEER_FILE.read_bytes()).hexdigest()[:8]
CODE_VERSION = f"1-data-{_DATA_DIGEST}"
"""The code version names the digest of the paper's and the peers' data files: editing them makes it stale."""


def _by_partition(context: dg.AssetExecutionContext, name: str, loaded) -> dict[str, pd.DataFrame]:
    """An all-partitions input as ``{partition: table}``: the IO manager gives a dict for several partitions, the
    table itself for one, and nothing where none is stored."""
    if loaded is None:
        return {}
    if isinstance(loaded, pd.DataFrame):
        (partition,) = context.asset_partition_keys_for_input(name)
        return {partition: loaded}
    return dict(loaded)


class BenchmarkConfig(dg.Config):
    """Run config of ``benchmark_table``, set by ``humancal update``."""

    left_out: dict[str, str] = {}
    """Partitions to leave out (not read even where a table is stored), each with the reason."""


def left_out_markdown(left_out: dict[str, str]) -> str:
    """The ``left_out`` metadata: one line per partition left out, with the reason."""
    return "\n".join(f"- {partition}: {reason}" for partition, reason in sorted(left_out.items())) or "none"


def build_benchmark_assets(sequence_assets: Sequence[dg.AssetsDefinition]) -> list[dg.AssetsDefinition]:
    """``benchmark_table`` and ``stage_timings`` over the per-sequence assets ``sequence_assets``.

    Args:
        sequence_assets: the per-sequence assets of the definitions: which of :data:`BENCHMARK_INPUTS` exist, and
            what ``stage_timings`` times.
    """
    specs = [spec for assets_def in sequence_assets for spec in assets_def.specs]
    present = {spec.key.to_user_string() for spec in specs}
    inputs = [name for name in BENCHMARK_INPUTS if name in present]
    ins = {name: dg.AssetIn(key=name, partition_mapping=dg.AllPartitionMapping(),
                            metadata={"allow_missing_partitions": True}) for name in inputs}

    @dg.asset(name="benchmark_table", group_name=GROUP, ins=ins,
              metadata={**table_metadata("benchmark"), FAN_IN_CONFIG_KEY: True},
              code_version=CODE_VERSION, automation_condition=UPDATE_CONDITION)
    def benchmark_table_asset(context: dg.AssetExecutionContext, config: BenchmarkConfig,
                              **stored: dict[str, pd.DataFrame]) -> dg.Output:
        """Every sequence's headline figures (``metric_tables`` and ``method_tables`` of every partition that has
        them, but those the update leaves out) beside the paper's numbers and the peers measured here, as one long
        table; the side-by-side markdown is in the metadata (``evaluation/benchmark.py``)."""
        for partition, reason in sorted(config.left_out.items()):
            context.log.warning(f"left out {partition}: {reason}")
        registered = sorted(context.instance.get_dynamic_partitions(SEQUENCES.name))
        tables, read = [], {}
        for name in BENCHMARK_INPUTS:
            if name not in stored:
                context.log.info(f"{name}: not among the definitions' assets: skipped")
                continue
            by_partition = _by_partition(context, name, stored[name])
            read[name] = [p for p in registered if p in by_partition and p not in config.left_out]
            missing = [p for p in registered if p not in by_partition and p not in config.left_out]
            if missing:
                context.log.info(f"{name}: no stored table for {', '.join(missing)}: skipped")
            tables += [normalise_metrics(by_partition[p]) for p in read[name]]
        metrics = pd.concat(tables, ignore_index=True) if tables else normalise_metrics(pd.DataFrame(
            columns=["dataset", "sequence", "method", "metric", "value", "unit"]))
        paper = paper_results()
        table = benchmark_table(metrics, paper, peer_results())
        markdown = benchmark_markdown(table)
        context.log.info(f"benchmark: {len(table)} rows from {len(tables)} stored tables")
        return table_output(
            table, "benchmark", rows=len(table),
            partitions=dg.MetadataValue.md("\n".join(f"- {name}: {', '.join(parts) or 'none'}"
                                                     for name, parts in read.items()) or "none"),
            left_out=dg.MetadataValue.md(left_out_markdown(config.left_out)),
            summary=dg.MetadataValue.md(markdown))

    return [benchmark_table_asset, build_stage_timings_asset(specs)]
