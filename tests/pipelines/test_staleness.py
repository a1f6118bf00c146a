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
