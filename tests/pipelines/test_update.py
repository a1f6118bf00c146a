"""`humancal update` semantics on toy assets (no external data): the real update condition, table outputs and
IO managers, on a small graph shaped like the real one::

    lifter (unpartitioned checkpoint) ──┐
    raw_detections ─> intrinsics ─> extrinsics ─> metric_tables ─> benchmark_table (unpartitioned, all partitions)

Missing -> everything; again -> nothing; a code change that alters the output -> that asset and its downstream;
a code change with identical output -> that asset only; a deleted or damaged artifact -> that asset, and its
downstream when the recomputed content differs; fan-in waits for every partition, also under ``--partition``.
"""

import dagster as dg
import pandas as pd
import pytest
import torch

from assets.common import ON_REQUEST_KEY, UPDATE_CONDITION, table_metadata, table_output, versioned_output
from pipelines.partitions import SEQUENCES
from pipelines.update import stale_asset_partitions, update
from resources.io_managers import (
    CheckpointIOManagerFactory,
    ParquetIOManagerFactory,
    checkpoint_content_version,
    partition_path,
)

PARTITIONS = ["toy__a", "toy__b"]
PER_PARTITION = ["raw_detections", "intrinsics", "extrinsics", "metric_tables"]


def _views(sequence: str, width_px: int) -> pd.DataFrame:
    return pd.DataFrame({"sequence": [sequence], "view": [0], "name": ["cam0"], "width_px": [width_px], "height_px": [480]})


def toy_defs(storage, code: dict | None = None, offset: dict | None = None, fail: str | None = None,
             with_trained: bool = False) -> dg.Definitions:
    """The toy graph; ``code`` bumps code versions, ``offset`` changes an asset's output, ``fail`` breaks one."""
    code, offset = code or {}, offset or {}

    def value(name, width):
        if name == fail:
            raise ValueError(f"{name} exploded")
        return width + offset.get(name, 0)

    def step(name, parent):
        @dg.asset(name=name, partitions_def=SEQUENCES, metadata=table_metadata("views"),
                  code_version=code.get(name, "1"), automation_condition=UPDATE_CONDITION,
                  ins={"upstream": dg.AssetIn(parent)})
        def _step(context: dg.AssetExecutionContext, upstream: pd.DataFrame, lifter: dict) -> dg.Output:
            width = int(upstream["width_px"].iloc[0]) + int(lifter["state_dict"]["w"].item())
            return table_output(_views(context.partition_key, value(name, width)), "views")

        return _step

    @dg.asset(io_manager_key="checkpoint_io_manager", code_version=code.get("lifter", "1"),
              automation_condition=UPDATE_CONDITION)
    def lifter() -> dg.Output:
        checkpoint = {"state_dict": {"w": torch.tensor([float(value("lifter", 1))])}, "config": {},
                      "train_subjects": [], "val_subjects": []}
        return versioned_output(checkpoint, checkpoint_content_version(checkpoint))

    @dg.asset(partitions_def=SEQUENCES, metadata=table_metadata("views"), code_version=code.get("raw_detections", "1"),
              automation_condition=UPDATE_CONDITION)
    def raw_detections(context: dg.AssetExecutionContext) -> dg.Output:
        return table_output(_views(context.partition_key, value("raw_detections", 640)), "views")

    @dg.asset(metadata=table_metadata("views"), code_version=code.get("benchmark_table", "1"),
              automation_condition=UPDATE_CONDITION)
    def benchmark_table(metric_tables: dict[str, pd.DataFrame]) -> dg.Output:
        rows = pd.concat([metric_tables[k] for k in sorted(metric_tables)], ignore_index=True)
        return table_output(rows.assign(view=range(len(rows))), "views")

    assets = [lifter, raw_detections, step("intrinsics", "raw_detections"), step("extrinsics", "intrinsics"),
              step("metric_tables", "extrinsics"), benchmark_table]
    if with_trained:
        @dg.asset(metadata={ON_REQUEST_KEY: "humancal train lifter", **table_metadata("views")})
        def lifter_trained() -> pd.DataFrame:
            raise AssertionError("an on-request asset must not be computed by an update")

        @dg.asset(metadata=table_metadata("views"), code_version="1")
        def trained_report(lifter_trained: pd.DataFrame) -> pd.DataFrame:
            return lifter_trained

        assets += [lifter_trained, trained_report]
    return dg.Definitions(
        assets=assets,
        resources={"io_manager": ParquetIOManagerFactory(base_path=str(storage)),
                   "checkpoint_io_manager": CheckpointIOManagerFactory(base_path=str(storage))},
    )


@pytest.fixture
def instance():
    # in memory: the same event log and staleness as on disk, ten times faster than SQLite files here
    inst = dg.DagsterInstance.ephemeral()
    inst.add_dynamic_partitions(SEQUENCES.name, PARTITIONS)
    return inst


@pytest.fixture
def storage(tmp_path):
    return tmp_path / "artifacts"


def _names(result) -> list[tuple[str, str | None]]:
    return sorted(result.materialized, key=lambda item: (item[0], item[1] or ""))


def _all(*names, partitions=PARTITIONS) -> list[tuple[str, str | None]]:
    return sorted(((n, p) for n in names for p in partitions), key=lambda item: (item[0], item[1] or ""))


def _path(storage, asset, partition=None, extension=".parquet"):
    return partition_path(str(storage), asset, partition, extension)


def test_missing_materializes_everything_upstream_first_then_nothing(instance, storage):
    first = update(toy_defs(storage), instance)
    assert _names(first) == sorted([("benchmark_table", None), ("lifter", None), *_all(*PER_PARTITION)],
                                   key=lambda item: (item[0], item[1] or ""))
    order = [name for name, _ in first.materialized]
    assert order.index("lifter") < order.index("intrinsics") < order.index("metric_tables") < order.index("benchmark_table")
    assert first.failed == () and first.waiting == ()
    again = update(toy_defs(storage), instance)
    assert again.count == 0 and again.rounds == 0
    assert stale_asset_partitions(toy_defs(storage), instance) == []


def test_a_new_partition_goes_through_the_graph_in_one_run_after_its_shared_inputs(instance, storage):
    rounds, stored = [], []
    first = update(toy_defs(storage), instance, on_round=lambda n, items: rounds.append(sorted(
        (key.to_user_string(), pk or "") for key, pk in items)),
        on_stored=lambda key, pk, seconds: stored.append((key.to_user_string(), pk)))
    assert sorted(stored, key=str) == sorted(first.materialized, key=str)  # each reported once, as it was stored
    # the lifter is missing: what reads it waits a round; then each partition's missing chain runs whole
    assert rounds == [sorted([("lifter", ""), *((n, p) for n, p in _all("raw_detections"))]),
                      _all("extrinsics", "intrinsics", "metric_tables"), [("benchmark_table", "")]]
    assert first.rounds == 3 and first.failed == ()


def test_a_step_failing_in_the_middle_of_a_run_fails_alone(instance, storage):
    result = update(toy_defs(storage, fail="intrinsics"), instance)
    assert sorted((n, p) for n, p, _ in result.failed) == _all("intrinsics")  # not what Dagster skipped after it
    assert not {"extrinsics", "metric_tables", "benchmark_table"} & {n for n, _ in result.materialized}
    [(name, _, reason)] = result.waiting
    assert name == "benchmark_table" and "intrinsics[toy__a] failed" in reason
    fixed = update(toy_defs(storage), instance)
    assert _names(fixed) == sorted([*_all("intrinsics", "extrinsics", "metric_tables"), ("benchmark_table", None)],
                                   key=lambda item: (item[0], item[1] or ""))


def test_code_change_with_new_output_recomputes_it_and_its_downstream(instance, storage):
    update(toy_defs(storage), instance)
    changed = toy_defs(storage, code={"extrinsics": "2"}, offset={"extrinsics": 1})
    result = update(changed, instance)
    assert _names(result) == sorted([("benchmark_table", None), *_all("extrinsics", "metric_tables")])
    assert update(changed, instance).count == 0


def test_code_change_with_identical_output_recomputes_only_that_asset(instance, storage):
    update(toy_defs(storage), instance)
    bumped = toy_defs(storage, code={"intrinsics": "2"})
    assert _names(update(bumped, instance)) == _all("intrinsics")
    assert update(bumped, instance).count == 0


def test_a_new_shared_input_relifts_every_partition(instance, storage):
    update(toy_defs(storage), instance)
    result = update(toy_defs(storage, code={"lifter": "2"}, offset={"lifter": 5}), instance)
    assert ("lifter", None) in result.materialized
    assert set(_all(*PER_PARTITION[1:])) <= set(result.materialized)
    assert ("raw_detections", "toy__a") not in result.materialized


def test_deleted_artifact_is_recomputed_and_its_downstream_kept_when_identical(instance, storage):
    defs = toy_defs(storage)
    update(defs, instance)
    path = _path(storage, "extrinsics", "toy__a")
    path.unlink()
    assert stale_asset_partitions(defs, instance) == [
        (dg.AssetKey("extrinsics"), "toy__a", f"its stored artifact is missing ({path})")
    ]
    result = update(defs, instance)
    assert _names(result) == [("extrinsics", "toy__a")]  # same content: metric_tables was computed from it
    assert path.exists()
    assert update(defs, instance).count == 0


def test_deleted_artifact_that_comes_back_different_recomputes_its_downstream(instance, storage):
    update(toy_defs(storage), instance)
    _path(storage, "extrinsics", "toy__b").unlink()
    # the code changed without a code_version bump: only the deleted partition is recomputed, with new content
    result = update(toy_defs(storage, offset={"extrinsics": 3}), instance)
    assert _names(result) == sorted([("benchmark_table", None), ("extrinsics", "toy__b"), ("metric_tables", "toy__b")])


def test_random_bytes_in_a_table_are_stale_with_their_downstream_on_new_content(instance, storage):
    defs = toy_defs(storage)
    update(defs, instance)
    path = _path(storage, "intrinsics", "toy__a")
    path.write_bytes(torch.randint(0, 256, (2048,), dtype=torch.uint8, generator=torch.Generator().manual_seed(0)).numpy().tobytes())
    [(key, partition, cause)] = stale_asset_partitions(defs, instance)
    assert (key.to_user_string(), partition) == ("intrinsics", "toy__a") and "unreadable" in cause
    assert _names(update(defs, instance)) == [("intrinsics", "toy__a")]
    assert update(defs, instance).count == 0


def test_a_valid_table_with_other_content_is_stale(instance, storage):
    defs = toy_defs(storage)
    update(defs, instance)
    other = _path(storage, "intrinsics", "toy__b").read_bytes()
    _path(storage, "intrinsics", "toy__a").write_bytes(other)  # readable, but not what was recorded
    [(key, partition, cause)] = stale_asset_partitions(defs, instance)
    assert (key.to_user_string(), partition) == ("intrinsics", "toy__a")
    assert "differs from its recorded data version" in cause
    assert _names(update(defs, instance)) == [("intrinsics", "toy__a")]


def test_a_damaged_checkpoint_is_recomputed(instance, storage):
    defs = toy_defs(storage)
    update(defs, instance)
    path = _path(storage, "lifter", None, ".pt")
    path.write_bytes(path.read_bytes()[:100])
    assert _names(update(defs, instance)) == [("lifter", None)]
    assert update(defs, instance).count == 0


def test_fan_in_waits_for_every_partition_also_under_partition(instance, storage):
    defs = toy_defs(storage)
    first = update(defs, instance, partitions=["toy__a"])
    assert ("benchmark_table", None) not in first.materialized
    assert ("metric_tables", "toy__a") in first.materialized and ("metric_tables", "toy__b") not in first.materialized
    [(name, partition, reason)] = first.waiting
    assert (name, partition) == ("benchmark_table", None)
    assert "all 2 partitions of metric_tables" in reason and "metric_tables[toy__b] is missing and outside --partition" in reason
    assert "left benchmark_table: waits for all 2 partitions" in first.waiting_lines()[0]
    # the other partition arrives: now every input is there, and the fan-in runs
    second = update(defs, instance, partitions=["toy__b"])
    assert ("benchmark_table", None) in second.materialized and second.waiting == ()
    table = pd.read_parquet(str(_path(storage, "benchmark_table")))
    assert sorted(table["sequence"]) == PARTITIONS
    # new code for every partition, updated under --partition: the other partition's metric table is
    # materialized but computed from stale inputs, so the fan-in waits again, naming the stale root
    changed = toy_defs(storage, code={"raw_detections": "2"}, offset={"raw_detections": 1})
    third = update(changed, instance, partitions=["toy__a"])
    assert ("metric_tables", "toy__a") in third.materialized and ("benchmark_table", None) not in third.materialized
    [(name, _, reason)] = third.waiting
    assert name == "benchmark_table"
    assert "raw_detections[toy__b] is stale and outside --partition" in reason
    assert ("benchmark_table", None) in update(changed, instance, partitions=["toy__b"]).materialized


def test_fan_in_waits_when_a_partition_fails(instance, storage):
    result = update(toy_defs(storage, fail="metric_tables"), instance)
    assert sorted((n, p) for n, p, _ in result.failed) == _all("metric_tables")
    assert "ValueError: metric_tables exploded" in result.failed[0][2]
    assert ("benchmark_table", None) not in result.materialized
    [(name, _, reason)] = result.waiting
    assert name == "benchmark_table" and "metric_tables[toy__a] failed" in reason
    assert set(_all("raw_detections", "intrinsics", "extrinsics")) <= set(result.materialized)


def test_a_failure_leaves_out_only_its_descendants_in_that_partition(instance, storage):
    defs = toy_defs(storage)
    update(defs, instance)
    broken = toy_defs(storage, code={"intrinsics": "2", "raw_detections": "2"}, offset={"raw_detections": 2},
                      fail="intrinsics")
    result = update(broken, instance, partitions=["toy__a"])
    assert [(n, p) for n, p, _ in result.failed] == [("intrinsics", "toy__a")]
    assert _names(result) == [("raw_detections", "toy__a")]  # extrinsics and metric_tables were left out


def test_on_request_assets_are_never_computed_and_their_readers_wait(instance, storage):
    result = update(toy_defs(storage, with_trained=True), instance)
    assert "lifter_trained" not in [n for n, _ in result.materialized]
    assert ("trained_report", None, "waits for lifter_trained is computed on request (humancal train lifter) and is missing") in result.waiting
