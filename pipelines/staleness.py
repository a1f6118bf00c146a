"""Dagster's view of which asset partitions are missing or stale: the one module that uses Dagster's private API.

``humancal update`` asks, per asset partition, the question the Dagster UI answers with its "Missing" and
"Stale" labels: never materialized; or materialized by an older ``code_version``; or computed from an upstream
data version that has since changed. Dagster answers it in ``CachingStaleStatusResolver``, which is not public.

Why not the public ``dg.evaluate_automation_conditions`` (measured in the project's feasibility notes, and
``assets.common.UPDATE_CONDITION`` is written for it):

* Its ``since_last_handled`` terms need the evaluation cursor of the previous command, and persisting that cursor
  between two ``humancal update`` processes needs ``dagster._serdes`` (private too): one private call traded for
  another, plus a state file that can disagree with the event log.
* It evaluates every partition of every asset and requests one level of the graph per tick; an update restricted
  to ``--partition`` wants the answer for a few asset partitions, on demand, with a cause to print.
* Neither knows whether the stored file still exists or still holds what was recorded: that check is ours either
  way (``pipelines.update``).

What would replace this module: ``dg.evaluate_automation_conditions`` once its cursor can be serialized through a
public API, or a public staleness query (the one the UI's GraphQL ``staleStatus`` field uses). Everything private
stays here, behind :class:`StalenessView`; ``tests/pipelines/test_staleness.py`` exercises it on toy assets with no
external data, so a Dagster upgrade that moves these names fails there first.
"""

from __future__ import annotations

import enum
import hashlib
from dataclasses import dataclass

import dagster as dg
from dagster._core.asset_graph_view.asset_graph_view import AssetGraphView, TemporalContext
from dagster._core.definitions.data_version import (
    DATA_VERSION_IS_USER_PROVIDED_TAG,
    DATA_VERSION_TAG,
    CachingStaleStatusResolver,
    StaleCauseCategory,
    StaleStatus,
    get_input_data_version_tag,
)
from dagster._time import get_current_datetime

from resources.io_managers import STORED_FILE_KEY

__all__ = ["Freshness", "Recorded", "Status", "StalenessView", "io_manager_key"]


class Freshness(enum.Enum):
    """Dagster's verdict on one asset partition."""

    MISSING = "missing"
    STALE = "stale"
    FRESH = "fresh"


@dataclass(frozen=True)
class Status:
    """The freshness of one asset partition and, when not fresh, why (e.g. ``has a new code version``)."""

    freshness: Freshness
    cause: str = ""

    @property
    def fresh(self) -> bool:
        return self.freshness is Freshness.FRESH


@dataclass(frozen=True)
class Recorded:
    """What the latest materialization of an asset partition recorded.

    Attributes:
        data_version: its data version.
        user_provided: the asset computed that version itself (humancal's content hashes), rather than Dagster
            deriving one from code version and inputs.
        file_signature: size and modification time of the stored file right after it was written
            (``resources.io_managers.STORED_FILE_KEY``; ``None`` when not recorded).
        run_id: the run that materialized it.
    """

    data_version: str
    user_provided: bool
    file_signature: str | None = None
    run_id: str | None = None


_FRESHNESS = {StaleStatus.MISSING: Freshness.MISSING, StaleStatus.STALE: Freshness.STALE, StaleStatus.FRESH: Freshness.FRESH}


class StalenessView:
    """A snapshot of Dagster's staleness for ``defs`` in ``instance``; answers are cached, so take a new view
    after materializing anything.

    Args:
        defs: the definitions.
        instance: the instance holding the materialization history.
    """

    def __init__(self, defs: dg.Definitions, instance: dg.DagsterInstance):
        graph = defs.resolve_asset_graph()
        view = AssetGraphView(
            temporal_context=TemporalContext(effective_dt=get_current_datetime(), last_event_id=None),
            instance=instance,
            asset_graph=graph,
        )
        self._instance = instance
        self._resolver = CachingStaleStatusResolver(instance=instance, asset_graph=graph, loading_context=view)

    def status(self, key: dg.AssetKey, partition: str | None = None) -> Status:
        """Missing, stale (with the first cause, e.g. ``has a new dependency data version: detections``) or fresh."""
        freshness = _FRESHNESS[self._resolver.get_status(key, partition)]
        if freshness is Freshness.MISSING:
            return Status(freshness, "never materialized")
        if freshness is Freshness.FRESH:
            return Status(freshness)
        causes = self._resolver.get_stale_causes(key, partition)
        if not causes:
            return Status(freshness, "stale")
        causes = [cause for cause in causes if not self._consumed_current(key, partition, cause)]
        return Status(freshness, _describe(causes[0])) if causes else Status(Freshness.FRESH)

    def _consumed_current(self, key: dg.AssetKey, partition: str | None, cause) -> bool:
        """Whether a "new dependency data version" cause of ``(key, partition)`` on one partition of a partitioned
        input is wrong: the latest materialization of ``(key, partition)`` records, as the data version it read,
        Dagster's hash of that input partition's current data version.

        Dagster decides that cause by event ids, not data versions: the input counts as new when the input
        partition has a materialization after the event the step recorded reading. The step takes that event from
        the asset's latest materialization of any partition (``asset_keys.last_materialization``), which two
        processes storing materializations of the same asset at once can leave pointing at the earlier of the two
        (measured on the cluster, Postgres and two workers: ``associations[P]`` stored as event 3012, the asset's
        latest left at 3011, another partition's). Every later fit of ``P`` then records 3011 and is "stale" again,
        whatever it reads. The data versions settle it."""
        dependency = cause.dependency
        if cause.category is not StaleCauseCategory.DATA or dependency is None or dependency.partition_key is None:
            return False
        own = self._latest_tags(key, partition)
        current = self._latest_tags(dependency.asset_key, dependency.partition_key).get(DATA_VERSION_TAG)
        consumed = own.get(get_input_data_version_tag(dependency.asset_key))
        # Dagster's data version of the partitions of an input read by a step: the SHA-256 of their data versions
        # joined in partition order; here one partition
        return current is not None and consumed == hashlib.sha256(current.encode()).hexdigest()

    def _latest_tags(self, key: dg.AssetKey, partition: str | None) -> dict[str, str]:
        records = self._instance.fetch_materializations(
            dg.AssetRecordsFilter(asset_key=key, asset_partitions=[partition] if partition else None), limit=1
        ).records
        return dict(records[0].asset_materialization.tags or {}) if records else {}

    def recorded(self, key: dg.AssetKey, partition: str | None = None) -> Recorded | None:
        """The data version of the latest materialization (``None`` if never materialized)."""
        records = self._instance.fetch_materializations(
            dg.AssetRecordsFilter(asset_key=key, asset_partitions=[partition] if partition else None), limit=1
        ).records
        if not records:
            return None
        materialization = records[0].asset_materialization
        tags = materialization.tags or {}
        version = tags.get(DATA_VERSION_TAG)
        if version is None:
            return None
        signature = (materialization.metadata or {}).get(STORED_FILE_KEY)
        return Recorded(version, tags.get(DATA_VERSION_IS_USER_PROVIDED_TAG) == "true",
                        getattr(signature, "value", None), records[0].run_id)


def _describe(cause) -> str:
    if cause.dependency is None:
        return cause.reason
    dep = cause.dependency.asset_key.to_user_string()
    if cause.dependency.partition_key:
        dep += f"[{cause.dependency.partition_key}]"
    return f"{cause.reason}: {dep}"


def io_manager_key(defs: dg.Definitions, key: dg.AssetKey) -> str:
    """The resource key of the IO manager storing asset ``key`` (``io_manager`` unless the asset names another)."""
    return defs.resolve_assets_def(key).get_io_manager_key_for_asset_key(key)
