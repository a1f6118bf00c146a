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

__all__ = ["UpdateResult", "excluded_with_descendants", "stale_asset_partitions", "update"]


@dataclass(frozen=True)
class UpdateResult:
    """What an update did."""

    materialized: tuple[tuple[str, str | None], ...]
    """(asset key, partition key) pairs materialized, in order."""
    rounds: int
    failed: tuple[tuple[str, str | None, str], ...] = ()
    """(asset key, partition key, error message) of the asset partitions whose computation failed; what
    depends on them was left out (other partitions went on)."""

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


def _with_descendants(graph, keys: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
    out, todo = set(), list(keys)
    while todo:
        key = todo.pop()
        if key not in out:
            out.add(key)
            todo.extend(graph.get(key).child_keys)
    return out


def _shared_ancestors(graph) -> set[dg.AssetKey]:
    """Unpartitioned assets upstream of a partitioned one (shared inputs such as the lifter checkpoint)."""
    out, todo = set(), [k for k in graph.materializable_asset_keys if graph.get(k).partitions_def is not None]
    seen = set()
    while todo:
        key = todo.pop()
        for parent in graph.get(key).parent_keys:
            if parent in seen or parent not in graph.materializable_asset_keys:
                continue
            seen.add(parent)
            if graph.get(parent).partitions_def is None:
                out.add(parent)
            todo.append(parent)
    return out


def stale_asset_partitions(
    defs: dg.Definitions,
    instance: dg.DagsterInstance,
    partitions: Iterable[str] | None = None,
    exclude: Iterable[dg.AssetKey] = (),
    blocked: Iterable[tuple[dg.AssetKey, str | None]] = (),
) -> list[tuple[dg.AssetKey, str | None]]:
    """Asset partitions Dagster reports as MISSING or STALE.

    Args:
        defs: the definitions.
        instance: the Dagster instance holding materialization history.
        partitions: restrict partitioned assets to these keys (default: all registered ones). Unpartitioned
            assets are then considered only when they feed partitioned ones (e.g. the lifter checkpoint).
        exclude: assets not to consider (e.g. those whose external data is missing here); their descendants
            are left out too, since they could not be computed.
        blocked: asset partitions not to consider (``None`` partition: in every partition).
    """
    blocked = set(blocked)
    resolver = _resolver(defs, instance)
    graph = defs.resolve_asset_graph()
    registered = set(instance.get_dynamic_partitions(SEQUENCES.name))
    wanted = registered if partitions is None else registered & set(partitions)
    out = []
    excluded = _with_descendants(graph, exclude)
    shared = _shared_ancestors(graph)
    for key in sorted(graph.materializable_asset_keys, key=lambda k: k.to_user_string()):
        if key in excluded:
            continue
        node = graph.get(key)
        if (key, None) in blocked:
            continue
        if node.partitions_def is None:
            if (partitions is None or key in shared) and resolver.get_status(key) != StaleStatus.FRESH:
                out.append((key, None))
            continue
        for pk in sorted(wanted):
            if (key, pk) not in blocked and resolver.get_status(key, pk) != StaleStatus.FRESH:
                out.append((key, pk))
    return out


def excluded_with_descendants(defs: dg.Definitions, exclude: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
    """The assets an update leaves out when ``exclude`` cannot be computed: those and everything downstream."""
    return _with_descendants(defs.resolve_asset_graph(), exclude)


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

    A failing asset partition does not stop the update: it is reported in ``UpdateResult.failed`` and what
    depends on it (in that partition; everywhere for an unpartitioned asset) is left out.

    Raises:
        RuntimeError: something is still stale after ``max_rounds`` rounds.
    """
    partitions = None if partitions is None else list(partitions)
    exclude = list(exclude)
    graph = defs.resolve_asset_graph()
    done: list[tuple[str, str | None]] = []
    failed: list[tuple[str, str | None, str]] = []
    blocked: set[tuple[dg.AssetKey, str | None]] = set()
    for round_no in range(1, max_rounds + 1):
        todo = stale_asset_partitions(defs, instance, partitions, exclude, blocked)
        if not todo:
            return UpdateResult(tuple(done), round_no - 1, tuple(failed))
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
                raise_on_error=False,
            )
            produced = {e.asset_key for e in result.get_asset_materialization_events()}
            done.extend((key.to_user_string(), pk) for key in keys if key in produced)
            if result.success:
                continue
            message = "; ".join(_first_line(e) for e in result.get_step_failure_events()) or "run failed"
            for key in keys:
                if key not in produced:
                    failed.append((key.to_user_string(), pk, message))
                    blocked.update((k, pk) for k in _with_descendants(graph, [key]))
                    log.error("%s%s failed: %s", key.to_user_string(), f"[{pk}]" if pk else "", message)
    raise RuntimeError(f"still stale after {max_rounds} rounds: {stale_asset_partitions(defs, instance, partitions, exclude)[:5]}")


def _first_line(event) -> str:
    error = event.step_failure_data.error if event.step_failure_data else None
    while error is not None and error.cause is not None and "dagster" in error.cls_name.lower():
        error = error.cause  # Dagster wraps user errors: report the user's
    if error is None:
        return f"step {event.step_key} failed"
    return f"{event.step_key}: {error.cls_name}: {error.message.strip().splitlines()[0]}"
