"""benchmark_table and stage_timings on the real definitions, from a temporary instance with a small fake metric
table stored for one partition (nothing upstream is computed)."""

import dagster as dg
import pandas as pd
import pyarrow.parquet as pq

from humancal.tables.schemas import to_arrow
from pipelines.definitions import build_definitions
from pipelines.partitions import SEQUENCES
from resources.datasets import DatasetsResource
from resources.io_managers import partition_path, stored_content_version

STORED, MISSING = "synthetic__demo", "synthetic__tiny"


def _store(storage, asset, partition, method, figures, instance):
    table = pd.DataFrame({"dataset": "synthetic", "sequence": partition.split("__")[1], "method": method,
                          "metric": list(figures), "view": pd.array([None] * len(figures), dtype="Int32"),
                          "value": list(figures.values()), "unit": "u", "failed_checks": ""})
    path = partition_path(storage, asset, partition)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(to_arrow(table, "metrics"), str(path))
    instance.report_runless_asset_event(dg.AssetMaterialization(asset, partition=partition))


def test_benchmark_table_reads_the_stored_partitions_and_skips_the_others(tmp_path):
    storage = str(tmp_path / "artifacts")
    defs = build_definitions(storage, datasets=DatasetsResource(data_dir=str(tmp_path / "no_data")))
    graph = defs.resolve_asset_graph()
    benchmark = graph.get(dg.AssetKey("benchmark_table"))
    # every partition of its inputs through the graph (lineage), the on-request method_tables too
    assert benchmark.partitions_def is None and {"metric_tables", "method_tables"} == {
        key.to_user_string() for key in benchmark.parent_keys}
    assert all(not graph.get(k).partitions_def for k in graph.materializable_asset_keys
               if graph.get(k).group_name == benchmark.group_name)  # a group selection never mixes partitionings
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions(SEQUENCES.name, [STORED, MISSING])
    _store(storage, "metric_tables", STORED, "init", {"focal_error_pct": 2.5, "mpjpe_mm": 40.0}, instance)
    if "method_tables" in {k.to_user_string() for k in graph.materializable_asset_keys}:
        _store(storage, "method_tables", STORED, "no_skip", {"mpjpe_mm": 41.0}, instance)

    result = dg.materialize(list(defs.assets), resources=defs.resources, instance=instance,
                            selection=dg.AssetSelection.assets("benchmark_table", "stage_timings"))
    assert result.success
    stored = pd.read_parquet(str(partition_path(storage, "benchmark_table", None)))
    ours = stored[stored["source"] == "humancal"]
    assert set(ours["sequence"]) == {"demo"} and 2.5 in ours["value"].tolist()
    assert (stored["source"] == "paper").sum() > 300
    events = {e.asset_key.to_user_string(): e.materialization for e in result.get_asset_materialization_events()}
    meta = events["benchmark_table"].metadata
    assert "Synthetic scenes: synthetic / demo" in meta["summary"].value and STORED in meta["partitions"].value
    recorded = events["benchmark_table"].tags["dagster/data_version"]
    assert stored_content_version(partition_path(storage, "benchmark_table", None), "table", "benchmark") == recorded
    logs = " ".join(e.user_message for e in instance.all_logs(result.run_id) if e.user_message)
    assert f"metric_tables: no stored table for {MISSING}: skipped" in logs

    timings = pd.read_parquet(str(partition_path(storage, "stage_timings", None)))
    assert set(timings["sequence"]) == {STORED}  # the runless materialization has no step: no seconds
    assert timings.loc[timings["asset"] == "total", "seconds"].isna().all()
    recorded = events["stage_timings"].tags["dagster/data_version"]
    assert stored_content_version(partition_path(storage, "stage_timings", None), "table", "stage_timings") == recorded


def test_benchmark_table_leaves_out_what_the_update_says_and_says_why(tmp_path):
    from pipelines.cli.benchmark_report import left_out_lines

    storage = str(tmp_path / "artifacts")
    defs = build_definitions(storage, datasets=DatasetsResource(data_dir=str(tmp_path / "no_data")))
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions(SEQUENCES.name, [STORED, MISSING])
    _store(storage, "metric_tables", STORED, "init", {"focal_error_pct": 2.5}, instance)
    _store(storage, "metric_tables", MISSING, "init", {"focal_error_pct": 99.0}, instance)  # stored, but out of date
    reason = "extrinsics[synthetic__tiny] failed its blocking check rig_geometry"
    result = dg.materialize(list(defs.assets), resources=defs.resources, instance=instance,
                            selection=dg.AssetSelection.assets("benchmark_table"),
                            run_config={"ops": {"benchmark_table": {"config": {"left_out": {MISSING: reason}}}}})
    stored = pd.read_parquet(str(partition_path(storage, "benchmark_table", None)))
    assert set(stored.loc[stored["source"] == "humancal", "sequence"]) == {"demo"}
    [event] = result.get_asset_materialization_events()
    assert event.materialization.metadata["left_out"].value == f"- {MISSING}: {reason}"
    assert left_out_lines(instance) == [f"benchmark_table left out {MISSING}: {reason}"]
