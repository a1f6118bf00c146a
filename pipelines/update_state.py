"""The state of one ``humancal update`` (:class:`UpdateState`) and of one of its rounds (:class:`Round`): which asset
partitions are in scope, fresh, failed, held back or left out, and why (``pipelines.update`` drives them)."""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Iterable

import dagster as dg

from assets.checks import CheckOutcome, latest_check_outcomes
from pipelines.artifact_check import ArtifactCheck
from pipelines.failure_record import Failure, FailureRecord, attempt_fingerprint
from pipelines.partitions import SEQUENCES
from pipelines.staleness import Freshness, Recorded, StalenessView, Status
from pipelines.update_graph import UpdateGraph
from pipelines.update_result import UpdateResult, asset_name

__all__ = ["AssetPartition", "Round", "UpdateState"]

AssetPartition = tuple[dg.AssetKey, str | None]


class Round:
    """The state of the asset partitions in scope, as one round of the update sees it."""

    def __init__(self, update: UpdateState):
        self.u = update
        self.view = StalenessView(update.defs, update.instance)
        self.cache: dict[AssetPartition, Status] = {}
        self.behind_memo: dict[AssetPartition, set[AssetPartition]] = {}
        self._recorded: dict[AssetPartition, Recorded | None] = {}

    def status(self, key: dg.AssetKey, pk: str | None) -> Status:
        if (key, pk) not in self.cache:
            status = self.view.status(key, pk)
            if status.fresh and (key, pk) not in self.u.written:
                problem = self.u.artifacts.problem(self.view, key, pk)
                if problem:
                    status = Status(Freshness.STALE, problem)
            self.cache[(key, pk)] = status
        return self.cache[(key, pk)]

    def recorded(self, key: dg.AssetKey, pk: str | None) -> Recorded | None:
        if (key, pk) not in self._recorded:
            self._recorded[(key, pk)] = self.view.recorded(key, pk)
        return self._recorded[(key, pk)]

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
        unpartitioned asset reading a partitioned one, every registered partition not left out (failed or held
        back by a failed blocking check)."""
        out = []
        for parent in self.u.graph.parents[key]:
            if not self.u.graph.partitioned(parent):
                out.append((parent, None))
            elif pk is not None:
                out.append((parent, pk))
            else:
                out.extend((parent, q) for q in self.u.registered if (parent, q) not in self.u.blocked)
        return out

    def left_out(self, key: dg.AssetKey) -> dict[str, str]:
        """The partitions the fan-in asset ``key`` is computed without, and why."""
        out: dict[str, str] = {}
        for parent in self.u.graph.parents[key]:
            if self.u.graph.partitioned(parent):
                for q in self.u.registered:
                    if (parent, q) in self.u.blocked:
                        out.setdefault(q, self.u.blocked[(parent, q)])
        return out

    def runnable(self, item: AssetPartition) -> bool:
        """Every input is up to date (and a fan-in has at least one partition of each partitioned input left)."""
        if any(self.behind(parent) for parent in self.inputs(*item)):
            return False
        return not self.u.all_left_out(item)


class UpdateState:
    """What one update knows: scope, written, failed, held back and blocked asset partitions, and check outcomes."""

    def __init__(self, defs: dg.Definitions, instance: dg.DagsterInstance, partitions: Iterable[str] | None,
                 exclude: Iterable[dg.AssetKey], failures: FailureRecord):
        self.defs, self.instance, self.failures = defs, instance, failures
        self.graph = UpdateGraph(defs)
        self.registered = sorted(instance.get_dynamic_partitions(SEQUENCES.name))
        self.partitions = None if partitions is None else sorted(set(partitions))
        self.wanted = self.registered if self.partitions is None else [p for p in self.registered if p in self.partitions]
        self.excluded = self.graph.with_descendants(exclude)
        self.artifacts = ArtifactCheck(defs, self.graph)
        self.written: set[AssetPartition] = set()
        self.blocked: dict[AssetPartition, str] = {}
        """Asset partitions not to compute (a failed or held-back ancestor), and why."""
        self.failed: dict[AssetPartition, str] = {}
        self.earlier_failed: dict[AssetPartition, Failure] = {}
        self.held: dict[AssetPartition, str] = {}
        self.left_out: list[tuple[str, str, str]] = []
        self.checks: dict[tuple[str, str | None, str], CheckOutcome] = {}
        self.earlier: set[tuple[str, str | None, str]] = set()
        self.outcomes: dict[AssetPartition, tuple[CheckOutcome, ...]] = {}
        self._configs: dict[str, str] = {}

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

    def block(self, key: dg.AssetKey, pk: str | None, reason: str, scope: set[AssetPartition] | None = None) -> None:
        """Compute neither ``(key, pk)`` nor what depends on it in that partition (everywhere when ``pk`` is
        ``None``); a fan-in reader is not blocked by one partition: it leaves that partition out."""
        for k in self.graph.with_descendants([key]):
            if not self.graph.partitioned(k):
                items = [] if pk is not None else [(k, None)]
            else:
                items = [(k, pk)] if pk is not None else [(k, q) for q in self.registered]
            for item in items:
                self.blocked.setdefault(item, reason)
                if scope is not None and item in scope:
                    self.held.setdefault(item, reason)

    def hold(self, r: Round, item: AssetPartition, scope: set[AssetPartition]) -> bool:
        """Hold ``item`` and what is computed from it back if an input failed a blocking check; says whether."""
        failing = [(parent, outcome) for parent in r.inputs(*item) for outcome in self.blocking_failures(parent)]
        if not failing:
            return False
        for parent, outcome in failing:
            self.note_checks([outcome], earlier=parent not in self.written)
        reason = "held back: " + "; ".join(f"{o.where} failed its blocking check {o.check}" for _, o in failing)
        self.block(*item, reason, scope)
        return True

    def all_left_out(self, item: AssetPartition) -> bool:
        """A fan-in ``item`` whose partitioned input has every registered partition left out."""
        key, pk = item
        if pk is not None or not self.registered:
            return False
        return any(self.graph.partitioned(parent) and all((parent, q) in self.blocked for q in self.registered)
                   for parent in self.graph.parents[key])

    def recall_failures(self, r: Round) -> None:
        """Leave out what failed in an earlier update when nothing it is computed from changed since, unless its
        partition is asked for by name; forget the failures that are gone (fresh now, or no longer registered)."""
        for failure in self.failures.all():
            key, pk = dg.AssetKey.from_user_string(failure.asset), failure.partition
            if key not in self.graph.specs or pk not in self.registered or r.status(key, pk).fresh:
                self.failures.forget(failure.asset, pk)
                continue
            if (self.partitions is not None and pk in self.partitions) or self.fingerprint(r, key, pk) != failure.fingerprint:
                continue  # retried
            self.earlier_failed[(key, pk)] = failure
            self.block(key, pk, f"{failure.name} failed in an earlier update ({failure.when_text}): {failure.message}")

    def fingerprint(self, r: Round, key: dg.AssetKey, pk: str | None) -> str:
        """What computing ``(key, pk)`` depends on (``pipelines.failure_record.attempt_fingerprint``)."""
        inputs = {}
        for k, q in r.inputs(key, pk):
            recorded = r.recorded(k, q)
            inputs[asset_name(k.to_user_string(), q)] = recorded.data_version if recorded else None
        return attempt_fingerprint(self.graph.code_version(key), inputs, self._sequence_config(pk))

    def _sequence_config(self, pk: str | None) -> str:
        """The partition's entry in the datasets config (its loader options), as text; empty where unknown."""
        if pk is None:
            return ""
        if pk not in self._configs:
            datasets = self.defs.resources.get("datasets")
            try:
                spec = datasets.spec(pk) if hasattr(datasets, "spec") else None
            except ValueError:  # not in the datasets config (e.g. a test's partitions)
                spec = None
            self._configs[pk] = json.dumps([spec.kind, spec.options], sort_keys=True, default=str) if spec else ""
        return self._configs[pk]

    def result(self, done: list[tuple[str, str | None]], rounds: int, waiting: Iterable) -> UpdateResult:
        # A blocking check that failed before this update still holds back what depends on its asset partition,
        # also when nothing here had to wait for it this time (its descendants were computed before it failed).
        for item in self.scope():
            if item not in self.written:
                self.note_checks(self.blocking_failures(item), earlier=True)
        held = [(key.to_user_string(), pk, reason) for (key, pk), reason in self.held.items()]
        failed = tuple((key.to_user_string(), pk, message) for (key, pk), message in self.failed.items())
        earlier = tuple(f for (_, pk), f in self.earlier_failed.items() if pk is None or pk in self.wanted)
        return UpdateResult(
            tuple(done), rounds, failed, (*held, *waiting), tuple(self.checks.values()),
            tuple(self.checks[name] for name in self.checks if name in self.earlier), earlier,
            tuple(self.left_out), tuple(self.partitions or ()),
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

    def why_not(self, r: Round, parent: AssetPartition) -> str:
        """Why an input that is not fresh will not be brought up to date by this update."""
        key, pk = parent
        name = asset_name(key.to_user_string(), pk)
        if parent in self.failed:
            return f"{name} failed"
        if parent in self.held:
            return f"{name} is {self.held[parent]}"
        if parent in self.blocked:
            return self.blocked[parent]
        command = self.graph.on_request(key)
        if command:
            return f"{name} is computed on request ({command}) and is {r.status(key, pk).freshness.value}"
        if key in self.excluded:
            return f"{name} cannot be computed here (its data is missing)"
        if pk is not None and pk not in self.wanted:
            return f"{name} is {r.status(key, pk).freshness.value} and outside --partition"
        return f"{name} is {r.status(key, pk).freshness.value} ({r.status(key, pk).cause})"

    def waiting_reason(self, r: Round, item: AssetPartition, pending: set[AssetPartition]) -> str:
        """Why ``item`` cannot run: the inputs (or their ancestors) this update cannot bring up to date."""
        reasons: dict[dg.AssetKey, list[str]] = defaultdict(list)
        for parent in r.inputs(*item):
            for key, pk in sorted(r.behind(parent), key=lambda b: (b[0].to_user_string(), b[1] or "")):
                name = asset_name(key.to_user_string(), pk)
                why = f"{name} is left too" if (key, pk) in pending else self.why_not(r, (key, pk))
                if why not in reasons[parent[0]]:
                    reasons[parent[0]].append(why)
        if self.all_left_out(item):
            for parent in self.graph.parents[item[0]]:
                reasons[parent].extend(self.blocked[(parent, q)] for q in self.registered if (parent, q) in self.blocked)
        parts = []
        for key, why in reasons.items():
            if item[1] is None and self.graph.partitioned(key):
                head = f"waits for all {len(self.registered)} partitions of {key.to_user_string()} to be up to date"
                parts.append(f"{head}: {'; '.join(why[:3])}{' ...' if len(why) > 3 else ''}")
            else:
                parts.append(f"waits for {'; '.join(why)}")
        return "; ".join(parts) or "an input is not up to date"
