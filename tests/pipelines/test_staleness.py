"""The adapter around Dagster's private staleness API, on two toy assets (no external data).

If a Dagster upgrade moves the private names ``pipelines.staleness`` imports, this file fails first.
"""

import dagster as dg
import pandas as pd
import pytest

from pipelines.staleness import Freshness, StalenessView, io_manager_key


def _defs(code_version: str = "1", value: int = 1) -> dg.Definitions:
    @dg.asset(code_version=code_version)
    def parent() -> dg.Output:
        return dg.Output(pd.DataFrame({"x": [value]}), data_version=dg.DataVersion(f"v{value}"))

    @dg.asset(code_version="1", io_manager_key="other_io_manager")
    def child(parent: pd.DataFrame) -> pd.DataFrame:
        return parent

    io = dg.InMemoryIOManager()
    return dg.Definitions(assets=[parent, child], resources={"io_manager": io, "other_io_manager": io})


def _run(defs: dg.Definitions, instance, *names: str) -> None:
    selection = dg.AssetSelection.assets(*names)
    assert dg.materialize(list(defs.assets), resources=defs.resources, instance=instance, selection=selection).success


@pytest.mark.filterwarnings("ignore::dagster.BetaWarning")
def test_missing_then_fresh_then_stale_with_a_cause():
    instance = dg.DagsterInstance.ephemeral()
    defs = _defs()
    view = StalenessView(defs, instance)
    assert view.status(dg.AssetKey("parent")).freshness is Freshness.MISSING
    assert view.recorded(dg.AssetKey("parent")) is None
    _run(defs, instance, "parent", "child")
    view = StalenessView(defs, instance)
    assert view.status(dg.AssetKey("child")).fresh
    recorded = view.recorded(dg.AssetKey("parent"))
    assert recorded.data_version == "v1" and recorded.user_provided
    assert not view.recorded(dg.AssetKey("child")).user_provided  # Dagster derived it

    bumped = _defs(code_version="2", value=2)
    view = StalenessView(bumped, instance)
    status = view.status(dg.AssetKey("parent"))
    assert status.freshness is Freshness.STALE and status.cause == "has a new code version"
    assert view.status(dg.AssetKey("child")).fresh  # Dagster flags the first stale asset of a chain only
    _run(bumped, instance, "parent")
    status = StalenessView(bumped, instance).status(dg.AssetKey("child"))
    assert status.freshness is Freshness.STALE and status.cause == "has a new dependency data version: parent"


def test_io_manager_key_names_the_assets_own():
    defs = _defs()
    assert io_manager_key(defs, dg.AssetKey("parent")) == "io_manager"
    assert io_manager_key(defs, dg.AssetKey("child")) == "other_io_manager"


def _partitioned_defs(versions: dict[str, str] | None = None) -> dg.Definitions:
    """``parent`` -> ``child`` over partitions a and b; ``parent``'s data version of a partition is ``versions``'s
    entry (read when it runs), else ``v-<partition>``."""
    partitions = dg.StaticPartitionsDefinition(["a", "b"])
    versions = {} if versions is None else versions

    @dg.asset(code_version="1", partitions_def=partitions)
    def parent(context: dg.AssetExecutionContext) -> dg.Output:
        version = versions.get(context.partition_key, f"v-{context.partition_key}")
        return dg.Output(pd.DataFrame({"x": [1]}), data_version=dg.DataVersion(version))

    @dg.asset(code_version="1", partitions_def=partitions)
    def child(parent: pd.DataFrame) -> pd.DataFrame:
        return parent

    return dg.Definitions(assets=[parent, child], resources={"io_manager": dg.FilesystemIOManager()})


def _materialize(defs: dg.Definitions, instance, name: str, partition: str) -> None:
    assert dg.materialize(list(defs.assets), instance=instance, partition_key=partition, resources=defs.resources,
                          selection=dg.AssetSelection.assets(name)).success


def _lose_the_latest_update(instance, key: dg.AssetKey, partition: str) -> None:
    """Leave the asset's latest materialization pointing at its earlier one of ``partition``: the state two
    processes storing materializations of ``key`` at once can leave ``asset_keys`` in (a lost update)."""
    from dagster._core.storage.event_log.schema import AssetKeyTable
    from dagster._serdes import serialize_value

    earlier = instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=key, asset_partitions=[partition]), limit=1).records[0]
    with instance.event_log_storage.index_connection() as connection:
        connection.execute(AssetKeyTable.update().where(AssetKeyTable.c.asset_key == key.to_string())
                           .values(last_materialization=serialize_value(earlier)))


@pytest.mark.filterwarnings("ignore::dagster.BetaWarning")
def test_a_lost_update_of_the_latest_materialization_does_not_leave_a_fresh_partition_stale(tmp_path):
    instance = dg.DagsterInstance.local_temp(str(tmp_path))
    defs = _partitioned_defs()
    _materialize(defs, instance, "parent", "a")
    _materialize(defs, instance, "parent", "b")
    _lose_the_latest_update(instance, dg.AssetKey("parent"), "a")
    _materialize(defs, instance, "child", "b")  # reads parent[b], but records parent[a]'s event as the one it read
    view = StalenessView(defs, instance)
    assert view._resolver.get_status(dg.AssetKey("child"), "b").value == "STALE"  # Dagster, by event ids
    assert view.status(dg.AssetKey("child"), "b").fresh  # by data versions: it read parent[b]'s current data
    _materialize(defs, instance, "parent", "b")  # computed again, the same data version
    assert StalenessView(defs, instance).status(dg.AssetKey("child"), "b").fresh


@pytest.mark.filterwarnings("ignore::dagster.BetaWarning")
def test_new_data_in_an_input_partition_still_makes_it_stale(tmp_path):
    instance = dg.DagsterInstance.local_temp(str(tmp_path))
    versions = {"b": "v1"}
    defs = _partitioned_defs(versions)
    _materialize(defs, instance, "parent", "b")
    _materialize(defs, instance, "child", "b")
    _lose_the_latest_update(instance, dg.AssetKey("parent"), "b")
    versions["b"] = "v2"
    _materialize(defs, instance, "parent", "b")
    status = StalenessView(defs, instance).status(dg.AssetKey("child"), "b")
    assert status.freshness is Freshness.STALE and status.cause == "has a new dependency data version: parent[b]"
