"""Materialize only what is missing or stale, asking Dagster which asset partitions those are.

Staleness is Dagster's own (the status the UI shows as "Missing" / "Stale"): an asset partition is
stale when its code_version differs from the one its last materialization recorded, or when an
upstream asset's data version differs from the one it was computed from. Every humancal asset
reports a content-hash data version, so an upstream rerun that reproduces the same table does not
make its descendants stale.

Dagster flags only the first stale asset of a chain (its children are fresh until it reruns and
produces different data), so the update runs in rounds: materialize the stale asset partitions
whose upstream is up to date, ask again, until nothing is left.
"""

from __future__ import annotations

import logging
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import dagster as dg
from dagster._core.definitions.data_version import CachingStaleStatusResolver, StaleStatus
from dagster._core.asset_graph_view.asset_graph_view import AssetGraphView, TemporalContext
from dagster._time import get_current_datetime

from pipelines.partitions import SEQUENCES

log = logging.getLogger(__name__)

__all__ = ["UpdateResult", "stale_asset_partitions", "update"]


@dataclass(frozen=True)
class UpdateResult:
    """What an update did."""

    materialized: tuple[tuple[str, str | None], ...]
    """(asset key, partition key) pairs materialized, in order."""
    rounds: int

    @property
    def count(self) -> int:
        return len(self.materialized)


def _resolver(defs: dg.Definitions, instance: dg.DagsterInstance) -> CachingStaleStatusResolver:
    graph = defs.resolve_asset_graph()
    view = AssetGraphView(
        temporal_context=TemporalContext(effective_dt=get_current_datetime(), last_event_id=None),
        instance=instance,
        asset_graph=graph,
    )
    return CachingStaleStatusResolver(instance=instance, asset_graph=graph, loading_context=view)


def stale_asset_partitions(
    defs: dg.Definitions,
    instance: dg.DagsterInstance,
    partitions: Iterable[str] | None = None,
    exclude: Iterable[dg.AssetKey] = (),
) -> list[tuple[dg.AssetKey, str | None]]:
    """Asset partitions Dagster reports as MISSING or STALE.

    Args:
        defs: the definitions.
        instance: the Dagster instance holding materialization history.
        partitions: restrict partitioned assets to these keys (default: all registered ones).
            Unpartitioned assets are considered only when no restriction is given.
        exclude: assets not to consider (e.g. those whose external data is missing here).
    """
    resolver = _resolver(defs, instance)
    graph = defs.resolve_asset_graph()
    registered = set(instance.get_dynamic_partitions(SEQUENCES.name))
    wanted = registered if partitions is None else registered & set(partitions)
    out = []
    excluded = set(exclude)
    for key in sorted(graph.materializable_asset_keys, key=lambda k: k.to_user_string()):
        if key in excluded:
            continue
        node = graph.get(key)
        if node.partitions_def is None:
            if partitions is None and resolver.get_status(key) != StaleStatus.FRESH:
                out.append((key, None))
            continue
        for pk in sorted(wanted):
            if resolver.get_status(key, pk) != StaleStatus.FRESH:
                out.append((key, pk))
    return out


def update(
    defs: dg.Definitions,
    instance: dg.DagsterInstance,
    partitions: Iterable[str] | None = None,
    exclude: Iterable[dg.AssetKey] = (),
    max_rounds: int = 20,
    on_round: Callable[[int, list[tuple[dg.AssetKey, str | None]]], None] | None = None,
    run_config: dict | None = None,
) -> UpdateResult:
    """Materialize stale or missing asset partitions, upstream first, until none is left.

    Raises:
        RuntimeError: something is still stale after ``max_rounds`` rounds, or a run failed.
    """
    partitions = None if partitions is None else list(partitions)
    exclude = list(exclude)
    graph = defs.resolve_asset_graph()
    done: list[tuple[str, str | None]] = []
    for round_no in range(1, max_rounds + 1):
        todo = stale_asset_partitions(defs, instance, partitions, exclude)
        if not todo:
            return UpdateResult(tuple(done), round_no - 1)
        pending = set(todo)
        ready = [
            (key, pk)
            for key, pk in todo
            if not any((parent, pk) in pending or (parent, None) in pending for parent in graph.get(key).parent_keys)
        ]
        if on_round:
            on_round(round_no, ready)
        by_partition: dict[str | None, list[dg.AssetKey]] = defaultdict(list)
        for key, pk in ready:
            by_partition[pk].append(key)
        for pk, keys in by_partition.items():
            result = dg.materialize(
                assets=list(defs.assets),
                resources=defs.resources,
                selection=dg.AssetSelection.assets(*keys),
                partition_key=pk,
                instance=instance,
                run_config=run_config,
                raise_on_error=True,
            )
            if not result.success:
                raise RuntimeError(f"run for partition {pk} failed")
            done.extend((key.to_user_string(), pk) for key in keys)
    raise RuntimeError(f"still stale after {max_rounds} rounds: {stale_asset_partitions(defs, instance, partitions, exclude)[:5]}")
