"""Materialize only what is missing or stale: the engine of ``humancal update``.

An asset partition is recomputed when

* Dagster reports it missing or stale (:mod:`pipelines.staleness`): never materialized, a new ``code_version``,
  or an upstream asset whose data version changed since it was computed. Every humancal asset reports a
  content hash as its data version, so an upstream rerun that reproduces the same table leaves its
  descendants alone;
* or its stored artifact is not what the history says it is: the file is gone, unreadable, or its content hash
  (:func:`resources.io_managers.stored_content_version`, the function the assets' data versions come from) differs
  from the data version recorded by its last materialization. The stored artifacts are the truth. The
  recomputed artifact gets a new data version only if its content differs, and only then are its descendants
  recomputed: a deterministic asset restores what they were computed from.

Dagster flags only the first stale asset of a chain (its children stay fresh until it reruns and produces
different data), so the update runs in rounds: materialize what is not fresh and whose inputs are all fresh,
ask again, until nothing is left that can run.

An asset partition runs only when its inputs are up to date: fresh, and computed from fresh inputs, all the way
up. Fan-in follows from it: an unpartitioned asset reading every partition of a partitioned one (the benchmark
table reads every sequence's ``metric_tables``) runs only once every registered partition of that parent is
materialized and up to date, also under ``--partition``. A partition that is missing, stale, failed, left out
(data not here, computed on request) or outside ``--partition`` makes it wait: it is never computed from a partial
or mixed set, and :attr:`UpdateResult.waiting` says why it was left.

A failed blocking check (severity ERROR) holds back everything computed from the asset partition it checked.
Dagster does that within one run; the update runs one level of the graph per run, so it reads the check outcomes
of the latest materialization of every input before it runs anything (:func:`assets.checks.latest_check_outcomes`),
also when the check failed in an earlier update. :attr:`UpdateResult.checks` holds every failed check evaluated by
this update's runs, and the failing blocking checks of earlier runs that still hold something back.

Kill -9 in the middle of an update is safe: artifacts are written atomically and a materialization is recorded
only after its artifact is in place, so the next update finds the interrupted asset partitions missing or stale.
"""

from __future__ import annotations

import logging
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import dagster as dg
from upath import UPath

from assets.checks import CheckOutcome, latest_check_outcomes
from assets.common import ON_REQUEST_KEY
from pipelines.partitions import SEQUENCES
from pipelines.staleness import Freshness, StalenessView, Status, io_manager_key
from resources.io_managers import (
    ArtifactError,
    CheckpointIOManagerFactory,
    ParquetIOManagerFactory,
    TABLE_METADATA_KEY,
    partition_path,
    stored_content_version,
)

log = logging.getLogger(__name__)

__all__ = ["UpdateResult", "excluded_with_descendants", "stale_asset_partitions", "update"]

AssetPartition = tuple[dg.AssetKey, str | None]


@dataclass(frozen=True)
class UpdateResult:
    """What an update did."""

    materialized: tuple[tuple[str, str | None], ...]
    """(asset key, partition key) pairs materialized, in order."""
    rounds: int
    failed: tuple[tuple[str, str | None, str], ...] = ()
    """(asset key, partition key, error message) of the asset partitions whose computation failed; what
    depends on them was left out (other partitions went on)."""
    waiting: tuple[tuple[str, str | None, str], ...] = ()
    """(asset key, partition key, reason) of the asset partitions left missing or stale because an input could
    not be brought up to date here (e.g. a fan-in asset whose other partitions are outside ``--partition``), or
    held back by a failed blocking check upstream."""
    checks: tuple[CheckOutcome, ...] = ()
    """Every check that failed in this update's runs (warnings too), and the failing blocking checks recorded by
    earlier runs on asset partitions in scope (what depends on those was held back)."""
    earlier_checks: tuple[CheckOutcome, ...] = ()
    """Those of :attr:`checks` that were evaluated before this update (their asset partition was up to date)."""

    @property
    def count(self) -> int:
        return len(self.materialized)

    @property
    def blocking_failed(self) -> bool:
        """A blocking check failed: something downstream of it was not computed."""
        return any(outcome.blocks for outcome in self.checks)

    def waiting_lines(self) -> list[str]:
        """One line per waiting asset partition, for the user."""
        return [f"left {_name(key, pk)}: {reason}" for key, pk, reason in self.waiting]


def _name(key: str, pk: str | None) -> str:
    return f"{key}[{pk}]" if pk else key


class _Graph:
    """Parents, children and partitioning of the assets, from Dagster's public asset specs."""

    def __init__(self, defs: dg.Definitions):
        self.specs = {spec.key: spec for spec in defs.resolve_all_asset_specs()}
        self.parents = {key: [d.asset_key for d in spec.deps if d.asset_key in self.specs] for key, spec in self.specs.items()}
        self.children: dict[dg.AssetKey, list[dg.AssetKey]] = defaultdict(list)
        self.blocking_checked = {
            spec.asset_key for assets_def in defs.resolve_asset_graph().assets_defs
            for spec in assets_def.check_specs if spec.blocking
        } | {spec.asset_key for checks_def in (getattr(defs, "asset_checks", None) or [])
             for spec in checks_def.check_specs if spec.blocking}
        for key, parents in self.parents.items():
            for parent in parents:
                self.children[parent].append(key)

    def partitioned(self, key: dg.AssetKey) -> bool:
        return self.specs[key].partitions_def is not None

    def on_request(self, key: dg.AssetKey) -> str | None:
        return (self.specs[key].metadata or {}).get(ON_REQUEST_KEY)

    def with_descendants(self, keys: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
        return _closure(keys, self.children)

    def with_ancestors(self, keys: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
        return _closure(keys, self.parents)

    def sorted_keys(self) -> list[dg.AssetKey]:
        return sorted(self.specs, key=lambda k: k.to_user_string())


@dataclass
class _Artifacts:
    """Checks that a fresh asset partition's stored file still holds what its materialization recorded."""

    defs: dg.Definitions
    graph: _Graph
    checked: dict[AssetPartition, str | None] = field(default_factory=dict)

    def problem(self, view: StalenessView, key: dg.AssetKey, pk: str | None) -> str | None:
        """Why the stored artifact cannot be trusted (``None``: it can, or it is not ours to check). Cached."""
        if (key, pk) not in self.checked:
            self.checked[(key, pk)] = self._problem(view, key, pk)
        return self.checked[(key, pk)]

    def forget(self, key: dg.AssetKey, pk: str | None) -> None:
        self.checked.pop((key, pk), None)

    def _problem(self, view: StalenessView, key: dg.AssetKey, pk: str | None) -> str | None:
        where = self.location(key, pk)
        recorded = view.recorded(key, pk)
        # Only content-hash data versions can be checked against the file; an asset without a stored value
        # (e.g. a registry that reports metadata only) has no artifact.
        if where is None or recorded is None or not recorded.user_provided:
            return None
        path, kind, table = where
        try:
            version = stored_content_version(path, kind, table)
        except FileNotFoundError:
            return f"its stored artifact is missing ({path})"
        except ArtifactError as err:
            return f"its stored artifact is unreadable: {err}"
        if version != recorded.data_version:
            return f"its stored artifact ({path}) differs from its recorded data version"
        return None

    def location(self, key: dg.AssetKey, pk: str | None) -> tuple[UPath, str, str | None] | None:
        manager = self.defs.resources.get(io_manager_key(self.defs, key))
        if isinstance(manager, ParquetIOManagerFactory):
            kind, extension = "table", ".parquet"
        elif isinstance(manager, CheckpointIOManagerFactory):
            kind, extension = "checkpoint", ".pt"
        else:
            return None
        table = (self.graph.specs[key].metadata or {}).get(TABLE_METADATA_KEY)
        if kind == "table" and table is None:
            return None
        path = partition_path(manager.base_path, "/".join(key.path), pk, extension)
        return path, kind, table


class _Round:
    """The state of the asset partitions in scope, as one round of the update sees it."""

    def __init__(self, update: _Update):
        self.u = update
        self.view = StalenessView(update.defs, update.instance)
        self.cache: dict[AssetPartition, Status] = {}
        self.behind_memo: dict[AssetPartition, set[AssetPartition]] = {}

    def status(self, key: dg.AssetKey, pk: str | None) -> Status:
        if (key, pk) not in self.cache:
            status = self.view.status(key, pk)
            if status.fresh and (key, pk) not in self.u.written:
                problem = self.u.artifacts.problem(self.view, key, pk)
                if problem:
                    status = Status(Freshness.STALE, problem)
            self.cache[(key, pk)] = status
        return self.cache[(key, pk)]

    def behind(self, item: AssetPartition) -> set[AssetPartition]:
        """The asset partitions at or upstream of ``item`` that are not fresh, nearest first: ``item`` itself if it
        is not fresh, else what its inputs are behind (Dagster flags only the first stale asset of a chain, so a
        fresh asset can still read from a stale one's descendant)."""
        memo = self.behind_memo
        if item not in memo:
            memo[item] = set()  # the graph is acyclic; this only guards the recursion
            if not self.status(*item).fresh:
                memo[item] = {item}
            else:
                memo[item] = set().union(*(self.behind(parent) for parent in self.inputs(*item)))
        return memo[item]

    def inputs(self, key: dg.AssetKey, pk: str | None) -> list[AssetPartition]:
        """The asset partitions ``(key, pk)`` reads: the same partition, the unpartitioned parent, or, for an
        unpartitioned asset reading a partitioned one, every registered partition."""
        out = []
        for parent in self.u.graph.parents[key]:
            if not self.u.graph.partitioned(parent):
                out.append((parent, None))
            elif pk is not None:
                out.append((parent, pk))
            else:
                out.extend((parent, q) for q in self.u.registered)
        return out


class _Update:
    def __init__(self, defs, instance, partitions, exclude):
        self.defs, self.instance = defs, instance
        self.graph = _Graph(defs)
        self.registered = sorted(instance.get_dynamic_partitions(SEQUENCES.name))
        self.partitions = None if partitions is None else sorted(set(partitions))
        self.wanted = self.registered if self.partitions is None else [p for p in self.registered if p in self.partitions]
        self.excluded = self.graph.with_descendants(exclude)
        self.artifacts = _Artifacts(defs, self.graph)
        self.written: set[AssetPartition] = set()
        self.blocked: set[AssetPartition] = set()
        self.failed: dict[AssetPartition, str] = {}
        self.held: dict[AssetPartition, str] = {}
        self.checks: dict[tuple[str, str | None, str], CheckOutcome] = {}
        self.earlier: set[tuple[str, str | None, str]] = set()
        self.outcomes: dict[AssetPartition, tuple[CheckOutcome, ...]] = {}

    def blocking_failures(self, item: AssetPartition) -> list[CheckOutcome]:
        """The failed blocking checks of the latest materialization of ``item`` (cached until it is rewritten)."""
        if item[0] not in self.graph.blocking_checked:
            return []
        if item not in self.outcomes:
            self.outcomes[item] = latest_check_outcomes(self.instance, *item) or ()
        return [outcome for outcome in self.outcomes[item] if outcome.blocks]

    def note_checks(self, outcomes: Iterable[CheckOutcome], earlier: bool) -> None:
        """Remember the failed ones among ``outcomes`` for the result (the first report of a check wins)."""
        for outcome in outcomes:
            name = (outcome.asset, outcome.partition, outcome.check)
            if not outcome.passed and name not in self.checks:
                self.checks[name] = outcome
                if earlier:
                    self.earlier.add(name)

    def hold(self, r: _Round, item: AssetPartition, scope: set[AssetPartition]) -> bool:
        """Hold ``item`` and what is computed from it back if an input failed a blocking check; says whether."""
        failing = [(parent, outcome) for parent in r.inputs(*item) for outcome in self.blocking_failures(parent)]
        if not failing:
            return False
        for parent, outcome in failing:
            self.note_checks([outcome], earlier=parent not in self.written)
        reason = "held back: " + "; ".join(f"{o.where} failed its blocking check {o.check}" for _, o in failing)
        key, pk = item
        for k in self.graph.with_descendants([key]):
            if not self.graph.partitioned(k):
                keys = [] if pk is not None else [(k, None)]  # a fan-in reader waits for this partition
            else:
                keys = [(k, pk)] if pk is not None else [(k, q) for q in self.wanted]
            for held in keys:
                self.blocked.add(held)
                if held in scope:
                    self.held.setdefault(held, reason)
        return True

    def result(self, done: list[tuple[str, str | None]], rounds: int, waiting: Iterable) -> UpdateResult:
        # A blocking check that failed before this update still holds back what depends on its asset partition,
        # also when nothing here had to wait for it this time (its descendants were computed before it failed).
        for item in self.scope():
            if item not in self.written:
                self.note_checks(self.blocking_failures(item), earlier=True)
        held = [(key.to_user_string(), pk, reason) for (key, pk), reason in self.held.items()]
        return UpdateResult(
            tuple(done), rounds, _failed(self), (*held, *waiting), tuple(self.checks.values()),
            tuple(self.checks[name] for name in self.checks if name in self.earlier),
        )

    def scope(self) -> list[AssetPartition]:
        """The asset partitions this update may compute (on-request and excluded assets are not among them)."""
        graph = self.graph
        # Partitioned by sequence: assets computed on request only (the motion prior, partitioned by variant) are
        # never in scope and tie nothing (the mocap they train on is not a sequence's input).
        partitioned = [k for k in graph.specs if graph.partitioned(k) and not graph.on_request(k)]
        # Under --partition, only the unpartitioned assets tied to partitioned ones: their shared inputs (the
        # lifter checkpoint) and what reads them (fan-in).
        tied = graph.with_ancestors(partitioned) | graph.with_descendants(partitioned)
        out = []
        for key in graph.sorted_keys():
            if key in self.excluded or graph.on_request(key):
                continue
            if graph.partitioned(key):
                out.extend((key, pk) for pk in self.wanted)
            elif self.partitions is None or key in tied:
                out.append((key, None))
        return [item for item in out if item not in self.blocked and (item[0], None) not in self.blocked]

    def why_not(self, r: _Round, parent: AssetPartition) -> str:
        """Why an input that is not fresh will not be brought up to date by this update."""
        key, pk = parent
        name = _name(key.to_user_string(), pk)
        if parent in self.failed:
            return f"{name} failed"
        if parent in self.held:
            return f"{name} is {self.held[parent]}"
        command = self.graph.on_request(key)
        if command:
            return f"{name} is computed on request ({command}) and is {r.status(key, pk).freshness.value}"
        if key in self.excluded:
            return f"{name} cannot be computed here (its data is missing)"
        if pk is not None and pk not in self.wanted:
            return f"{name} is {r.status(key, pk).freshness.value} and outside --partition"
        return f"{name} is {r.status(key, pk).freshness.value} ({r.status(key, pk).cause})"

    def waiting_reason(self, r: _Round, item: AssetPartition, pending: set[AssetPartition]) -> str:
        """Why ``item`` cannot run: the inputs (or their ancestors) this update cannot bring up to date."""
        reasons: dict[dg.AssetKey, list[str]] = defaultdict(list)
        for parent in r.inputs(*item):
            for key, pk in sorted(r.behind(parent), key=lambda b: (b[0].to_user_string(), b[1] or "")):
                name = _name(key.to_user_string(), pk)
                why = f"{name} is left too" if (key, pk) in pending else self.why_not(r, (key, pk))
                if why not in reasons[parent[0]]:
                    reasons[parent[0]].append(why)
        parts = []
        for key, why in reasons.items():
            if item[1] is None and self.graph.partitioned(key):
                head = f"waits for all {len(self.registered)} partitions of {key.to_user_string()} to be up to date"
                parts.append(f"{head}: {'; '.join(why[:3])}{' ...' if len(why) > 3 else ''}")
            else:
                parts.append(f"waits for {'; '.join(why)}")
        return "; ".join(parts) or "an input is not up to date"


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
    u = _Update(defs, instance, partitions, exclude)
    r = _Round(u)
    return [(key, pk, r.status(key, pk).cause) for key, pk in u.scope() if not r.status(key, pk).fresh]


def excluded_with_descendants(defs: dg.Definitions, exclude: Iterable[dg.AssetKey]) -> set[dg.AssetKey]:
    """The assets an update leaves out when ``exclude`` cannot be computed: those and everything downstream."""
    return _Graph(defs).with_descendants(exclude)


def update(
    defs: dg.Definitions,
    instance: dg.DagsterInstance,
    partitions: Iterable[str] | None = None,
    exclude: Iterable[dg.AssetKey] = (),
    max_rounds: int = 20,
    on_round: Callable[[int, list[tuple[dg.AssetKey, str | None]]], None] | None = None,
    run_config: dict | None = None,
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

    Raises:
        RuntimeError: something could still run after ``max_rounds`` rounds.
    """
    u = _Update(defs, instance, None if partitions is None else list(partitions), list(exclude))
    done: list[tuple[str, str | None]] = []
    checks = list(getattr(defs, "asset_checks", None) or [])
    for round_no in range(1, max_rounds + 1):
        r = _Round(u)
        scope = u.scope()
        todo = [item for item in scope if not r.status(*item).fresh]
        ready = [item for item in todo if not any(r.behind(parent) for parent in r.inputs(*item))]
        ready = [item for item in ready if not u.hold(r, item, set(scope))]
        todo = [item for item in todo if item not in u.blocked and (item[0], None) not in u.blocked]
        pending = set(todo)
        if not ready:
            waiting = [(key.to_user_string(), pk, u.waiting_reason(r, (key, pk), pending)) for key, pk in todo]
            return u.result(done, round_no - 1, waiting)
        if on_round:
            on_round(round_no, ready)
        by_partition: dict[str | None, list[dg.AssetKey]] = defaultdict(list)
        for key, pk in ready:
            by_partition[pk].append(key)
        for pk, keys in by_partition.items():
            result = dg.materialize(
                assets=[*defs.assets, *checks],
                resources=defs.resources,
                selection=dg.AssetSelection.assets(*keys),
                partition_key=pk,
                instance=instance,
                run_config=run_config,
                raise_on_error=False,
            )
            produced = {e.asset_key for e in result.get_asset_materialization_events()}
            u.note_checks((CheckOutcome.of(e, pk) for e in result.get_asset_check_evaluations()), earlier=False)
            for key in keys:
                u.outcomes.pop((key, pk), None)
            for key in keys:
                if key in produced:
                    done.append((key.to_user_string(), pk))
                    u.written.add((key, pk))
                    u.artifacts.forget(key, pk)
            if result.success:
                continue
            # A failed blocking check fails its step after the asset was stored: reported in checks, not here.
            failures = [e for e in result.get_step_failure_events() if not _is_check_failure(e)]
            message = "; ".join(_first_line(e) for e in failures) or "run failed"
            for key in keys:
                if key not in produced:
                    u.failed[(key, pk)] = message
                    u.blocked.update((k, pk) for k in u.graph.with_descendants([key]))
                    log.error("%s failed: %s", _name(key.to_user_string(), pk), message)
    left = [(k.to_user_string(), pk) for k, pk in u.scope() if not _Round(u).status(k, pk).fresh]
    raise RuntimeError(f"still stale after {max_rounds} rounds: {left[:5]}")


def _failed(u: _Update) -> tuple[tuple[str, str | None, str], ...]:
    return tuple((key.to_user_string(), pk, message) for (key, pk), message in u.failed.items())


def _is_check_failure(event) -> bool:
    error = event.step_failure_data.error if event.step_failure_data else None
    return error is not None and error.cls_name == "DagsterAssetCheckFailedError"


def _first_line(event) -> str:
    error = event.step_failure_data.error if event.step_failure_data else None
    while error is not None and error.cause is not None and "dagster" in error.cls_name.lower():
        error = error.cause  # Dagster wraps user errors: report the user's
    if error is None:
        return f"step {event.step_key} failed"
    return f"{event.step_key}: {error.cls_name}: {error.message.strip().splitlines()[0]}"


def _closure(keys: Iterable[dg.AssetKey], edges: dict) -> set[dg.AssetKey]:
    """``keys`` and every asset reachable from them along ``edges`` (key -> neighbours)."""
    out, todo = set(), list(keys)
    while todo:
        key = todo.pop()
        if key not in out:
            out.add(key)
            todo.extend(edges[key])
    return out
