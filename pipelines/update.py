"""Materialize only what is missing or stale: the engine of ``humancal update``.

An asset partition is recomputed when

* Dagster reports it missing or stale (:mod:`pipelines.staleness`): never materialized, a new ``code_version``,
  or an upstream asset whose data version changed since it was computed. Every humancal asset reports a
  content hash as its data version, so an upstream rerun that reproduces the same table leaves its
  descendants alone;
* or its stored artifact is not what the history says it is (:mod:`pipelines.artifact_check`): the file is gone,
  unreadable, or its content hash differs from the data version recorded by its last materialization. The stored
  artifacts are the truth. The recomputed artifact gets a new data version only if its content differs, and only
  then are its descendants recomputed.

Dagster flags only the first stale asset of a chain (its children stay fresh until it reruns and produces
different data), so the update runs in rounds: materialize what is not fresh and whose inputs are all fresh,
ask again, until nothing is left that can run. What is missing (never materialized) downstream of a round's asset
partitions in the same sequence joins their run, since it is computed whatever they produce: a new capture goes
through the graph in one run, not one run per level (each run costs Dagster about a second of planning and events,
and on a cluster a round waits for its slowest capture). A step that computes several assets and cannot be subset
(the multi-assets ``association`` and ``body_fit``) is always run whole: one missing output recomputes all of them.

An asset partition runs only when its inputs are up to date: fresh, and computed from fresh inputs, all the way
up. An unpartitioned asset reading every partition of a partitioned one (fan-in: the benchmark table reads every
sequence's ``metric_tables``) waits until every registered partition of it is up to date, also under
``--partition``: a partition that is missing or stale makes it wait. A partition that failed, or that a failed
blocking check holds back, is left out instead: the fan-in is computed over the others and told which it left
out and why (``UpdateResult.left_out``); it waits when every partition is left out.

A failing asset partition does not stop the update: what depends on it (in that partition) is left out and the
other partitions go on. A failed partition is remembered (:mod:`pipelines.failure_record`): a later update does not
retry it while nothing it is computed from changed, unless its partition is named with ``--partition``. A failed
unpartitioned asset is retried by every update.

A failed blocking check (severity ERROR) holds back everything computed from the asset partition it checked.
Dagster does that within one run (it skips the steps after it); across runs, the update reads the check outcomes
of the latest materialization of every input before it runs anything (:func:`assets.checks.latest_check_outcomes`),
also when the check failed in an earlier update.

On a cluster (``HUMANCAL_CELERY_BROKER``: :mod:`pipelines.cluster`), the runs of a round start together and every
step runs on a Celery worker; what is recorded, and how failures and checks are handled, is the same.

Kill -9 in the middle of an update is safe: artifacts are written atomically and a materialization is recorded
only after its artifact is in place, so the next update finds the interrupted asset partitions missing or stale;
the runs it left "started" are marked failed by the next command that opens the instance
(:mod:`pipelines.run_guard`).
"""

from __future__ import annotations

import logging
from collections import defaultdict
from collections.abc import Callable, Iterable
from contextlib import nullcontext

import dagster as dg

from assets.checks import CheckOutcome
from pipelines.cluster import ClusterSettings, RunRequest, run_on_cluster
from pipelines.failure_record import FailureRecord
from pipelines.run_guard import run_tags
from pipelines.staleness import Freshness
from pipelines.update_graph import UpdateGraph
from pipelines.update_progress import StoredWatcher
from pipelines.update_result import UpdateResult, asset_name
from pipelines.update_state import AssetPartition, Round, UpdateState

log = logging.getLogger(__name__)

__all__ = ["UpdateResult", "excluded_with_descendants", "stale_asset_partitions", "update"]


def stale_asset_partitions(
    defs: dg.Definitions,
    instance: dg.DagsterInstance,
    partitions: Iterable[str] | None = None,
    exclude: Iterable[dg.AssetKey] = (),
) -> list[tuple[dg.AssetKey, str | None, str]]:
    """The asset partitions an update would consider: (asset key, partition key, cause), not fresh ones only.

    Args:
        defs: the definitions.
        instance: the Dagster instance holding materialization history.
        partitions: restrict partitioned assets to these keys (default: all registered ones). Unpartitioned
            assets are then considered only when tied to partitioned ones (their shared inputs, fan-in readers).
        exclude: assets not to consider (e.g. those whose external data is missing here), with their descendants.
    """
    u = UpdateState(defs, instance, partitions, exclude, FailureRecord())
    r = Round(u)
    return [(key, pk, r.status(key, pk).cause) for key, pk in u.scope() if not r.status(key, pk).fresh]


def excluded_with_descendants(defs: dg.Definitions, exclude: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
    """The assets an update leaves out when ``exclude`` cannot be computed: those and everything downstream."""
    return UpdateGraph(defs).with_descendants(exclude)


def update(
    defs: dg.Definitions,
    instance: dg.DagsterInstance,
    partitions: Iterable[str] | None = None,
    exclude: Iterable[dg.AssetKey] = (),
    max_rounds: int = 20,
    on_round: Callable[[int, list[tuple[dg.AssetKey, str | None]]], None] | None = None,
    run_config: dict | None = None,
    failures: FailureRecord | None = None,
    before_run: Callable[[], None] | None = None,
    cluster: ClusterSettings | None = None,
    on_run_done: Callable[[str | None, bool, int, int], None] | None = None,
    on_stored: Callable[[dg.AssetKey, str | None, float], None] | None = None,
) -> UpdateResult:
    """Materialize missing or stale asset partitions, upstream first, until nothing that can run is left.

    A failing asset partition does not stop the update: it is reported in ``UpdateResult.failed`` and what
    depends on it (in that partition; everywhere for an unpartitioned asset) is left out. Asset partitions
    whose inputs cannot be brought up to date here are reported in ``UpdateResult.waiting``. An asset partition
    whose input failed a blocking check is held back with its descendants (``UpdateResult.waiting``), and the
    failed checks are in ``UpdateResult.checks``.

    Args:
        defs: the definitions.
        instance: the Dagster instance holding materialization history.
        partitions: only these partitions of partitioned assets (default: every registered one).
        exclude: assets that cannot be computed here (their data is missing); their descendants are left out.
        max_rounds: a bound on the rounds (the graph's depth is far below it).
        on_round: called with the round number and the asset partitions about to be materialized.
        run_config: Dagster run config of every run (e.g. log level).
        failures: the failures of earlier updates (read and updated; saved at the end); default: none remembered.
        before_run: called once before the first run (e.g. to quiet a library that prints on initialisation).
        cluster: when given, every step runs on its Celery workers and the runs of a round (one per partition)
            run at the same time (:mod:`pipelines.cluster`); default: one run after the other, in this process.
        on_run_done: called as each run of a round ends, with its partition, whether it succeeded, how many runs
            of the round have ended and how many it has.
        on_stored: called as each asset partition of a round is stored, with its key, partition and the seconds
            since the round began (:class:`pipelines.update_progress.StoredWatcher`, from a thread of its own).

    Raises:
        RuntimeError: something could still run after ``max_rounds`` rounds.
    """
    u = UpdateState(defs, instance, None if partitions is None else list(partitions), list(exclude),
                    failures if failures is not None else FailureRecord())
    done: list[tuple[str, str | None]] = []
    u.recall_failures(Round(u))
    for round_no in range(1, max_rounds + 1):
        r = Round(u)
        scope = u.scope()
        todo = [item for item in scope if not r.status(*item).fresh]
        ready = [item for item in todo if r.runnable(item)]
        held = [item for item in ready if u.hold(r, item, set(scope))]
        ready = [item for item in ready if item not in held]
        if not ready:
            if held:
                continue  # a fan-in may now run without the partitions just held back
            todo = [item for item in todo if item not in u.blocked and (item[0], None) not in u.blocked]
            waiting = [(key.to_user_string(), pk, u.waiting_reason(r, (key, pk), set(todo))) for key, pk in todo]
            u.failures.save()
            return u.result(done, round_no - 1, waiting)
        steps = _steps_by_partition(u.graph, ready + _missing_after(u, r, ready, set(scope)))
        if on_round:
            on_round(round_no, [(key, pk) for pk, keys in steps.items() for key in keys])
        if before_run is not None:
            before_run()
            before_run = None
        items = [(key, pk) for pk, keys in steps.items() for key in keys]
        with StoredWatcher(instance, items, on_stored) if on_stored else nullcontext():
            if cluster is None:
                for n, (pk, keys) in enumerate(steps.items(), start=1):
                    succeeded = _run(u, r, pk, keys, run_config, done)
                    if on_run_done:
                        on_run_done(pk, succeeded, n, len(steps))
            else:
                _run_round_on_cluster(u, r, steps, run_config, done, cluster, on_run_done)
        u.failures.save()
    left = [(k.to_user_string(), pk) for k, pk in u.scope() if not Round(u).status(k, pk).fresh]
    raise RuntimeError(f"still stale after {max_rounds} rounds: {left[:5]}")


def _missing_after(u: UpdateState, r: Round, ready: list[AssetPartition],
                   scope: set[AssetPartition]) -> list[AssetPartition]:
    """The asset partitions that join the runs of ``ready``: those of a sequence never materialized (missing, not
    merely stale: this update computes them whatever their inputs produce) whose every input is up to date with no
    failed blocking check, or is computed before them in the same run. A new capture then goes through the graph
    in one run instead of one run per level; Dagster runs the steps upstream first, and skips what depends on a
    step that failed or on a blocking check that failed (:func:`_record` leaves those for the next round to hold
    back or leave out)."""
    selected = set(ready)
    joined = []
    for key in u.graph.upstream_first():
        if not u.graph.partitioned(key):
            continue
        for pk in u.wanted:
            item = (key, pk)
            if item in selected or item not in scope or r.status(*item).freshness is not Freshness.MISSING:
                continue
            inputs = r.inputs(*item)
            in_run = [parent in selected and parent[1] == pk for parent in inputs]
            if not any(in_run) or any(not here and (r.behind(parent) or u.blocking_failures(parent))
                                      for parent, here in zip(inputs, in_run)):
                continue
            selected.add(item)
            joined.append(item)
    return joined


def _steps_by_partition(graph: UpdateGraph, ready: list[AssetPartition]) -> dict[str | None, list[dg.AssetKey]]:
    """The keys to select per partition: the ready ones, with the other outputs of a step that cannot be subset."""
    by_partition: dict[str | None, list[dg.AssetKey]] = defaultdict(list)
    for key, pk in ready:
        for member in graph.step(key):
            if member not in by_partition[pk]:
                by_partition[pk].append(member)
    return by_partition


def _run(u: UpdateState, r: Round, pk: str | None, keys: list[dg.AssetKey], run_config: dict | None,
         done: list[tuple[str, str | None]]) -> bool:
    """Materialize ``keys`` of partition ``pk`` in one run, in this process, and record what it produced, failed
    and checked; returns whether the run succeeded."""
    config, left_out = _fan_in_config(u, r, pk, keys, run_config)
    result = dg.materialize(
        assets=[*u.defs.assets, *(getattr(u.defs, "asset_checks", None) or [])],
        resources=u.defs.resources,
        selection=dg.AssetSelection.assets(*keys),
        partition_key=pk,
        instance=u.instance,
        run_config=config,
        tags=run_tags(),
        raise_on_error=False,
    )
    _record(u, r, pk, keys, result, left_out, done)
    return result.success


def _run_round_on_cluster(u: UpdateState, r: Round, steps: dict[str | None, list[dg.AssetKey]],
                          run_config: dict | None, done: list[tuple[str, str | None]], cluster: ClusterSettings,
                          on_run_done: Callable[[str | None, bool, int, int], None] | None) -> None:
    """The runs of one round (one per partition) at the same time, every step on the cluster's workers; each is
    recorded as by :func:`_run`."""
    requests, left_outs = [], {}
    for pk, keys in steps.items():
        config, left_outs[pk] = _fan_in_config(u, r, pk, keys, run_config)
        requests.append(RunRequest(pk, tuple(k.to_user_string() for k in keys), config or {}))
    ended = []

    def report(request: RunRequest, result) -> None:
        ended.append(request)
        if on_run_done:
            on_run_done(request.partition, result.success, len(ended), len(requests))

    results = run_on_cluster(requests, u.instance, cluster, run_tags(), on_done=report)
    for (pk, keys), result in zip(steps.items(), results):
        _record(u, r, pk, keys, result, left_outs[pk], done)


def _record(u: UpdateState, r: Round, pk: str | None, keys: list[dg.AssetKey], result,
            left_out: dict[dg.AssetKey, dict[str, str]], done: list[tuple[str, str | None]]) -> None:
    """Record what the run of ``keys`` in partition ``pk`` produced, failed and checked (``result``: Dagster's
    execution result, in-process or not)."""
    produced = {e.asset_key for e in result.get_asset_materialization_events()}
    u.note_checks((CheckOutcome.of(e, pk) for e in result.get_asset_check_evaluations()), earlier=False)
    for key in keys:
        u.outcomes.pop((key, pk), None)
        if key in produced:
            done.append((key.to_user_string(), pk))
            u.written.add((key, pk))
            u.artifacts.forget(key, pk)
            u.failures.forget(key.to_user_string(), pk)
            u.left_out.extend((key.to_user_string(), q, why) for q, why in left_out.get(key, {}).items())
    if result.success:
        return
    # A failed blocking check fails its step after the asset was stored: reported in checks, not here.
    step_failures = result.get_step_failure_events()
    failures = [e for e in step_failures if not _is_check_failure(e)]
    message = "; ".join(_first_line(e) for e in failures) or "run failed"
    failed_steps = {e.step_key for e in failures}
    for key in keys:
        if key not in produced:
            if step_failures and u.defs.resolve_assets_def(key).node_def.name not in failed_steps:
                continue  # skipped after a step before it failed, or a blocking check did: the next round says so
            u.failed[(key, pk)] = message
            if pk is not None:  # a shared asset is retried by every update (it holds up every partition)
                u.failures.record(key.to_user_string(), pk, message, u.fingerprint(r, key, pk))  # inputs: untouched
            u.block(key, pk, f"{asset_name(key.to_user_string(), pk)} failed: {message}")
            log.info("%s failed: %s", asset_name(key.to_user_string(), pk), message)  # the CLI reports it


def _fan_in_config(u: UpdateState, r: Round, pk: str | None, keys: list[dg.AssetKey],
                   run_config: dict | None) -> tuple[dict | None, dict[dg.AssetKey, dict[str, str]]]:
    """The run config, with the partitions each fan-in asset among ``keys`` leaves out (those that take it)."""
    if pk is not None:
        return run_config, {}
    left_out = {key: r.left_out(key) for key in keys if u.graph.takes_left_out(key)}
    if not left_out:
        return run_config, {}
    ops = {u.defs.resolve_assets_def(key).node_def.name: {"config": {"left_out": parts}}
           for key, parts in left_out.items()}
    config = dict(run_config or {})
    config["ops"] = {**config.get("ops", {}), **ops}
    return config, left_out


def _is_check_failure(event) -> bool:
    error = event.step_failure_data.error if event.step_failure_data else None
    return error is not None and error.cls_name == "DagsterAssetCheckFailedError"


def _first_line(event) -> str:
    error = event.step_failure_data.error if event.step_failure_data else None
    while error is not None and error.cause is not None and "dagster" in error.cls_name.lower():
        error = error.cause  # Dagster wraps user errors: report the user's
    if error is None:
        return f"step {event.step_key} failed"
    message = error.message.strip().splitlines()[0] if error.message.strip() else ""
    if not message.startswith(f"{error.cls_name}:"):  # Dagster's serialized errors usually start with it
        message = f"{error.cls_name}: {message}"
    return f"{event.step_key}: {message}"
