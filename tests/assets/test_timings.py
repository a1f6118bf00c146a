"""The per-stage timing table from the run history, on toy assets shaped like the sequence graph."""

import time

import dagster as dg
import numpy as np
import pandas as pd

from assets.partitions import SEQUENCES
from assets.timings import build_stage_timings_asset, stage_timings_table, timed_graph


def _toy_assets():
    def step(name, deps, group="sequence", sleep=0.0):
        @dg.asset(name=name, partitions_def=SEQUENCES, group_name=group, deps=deps)
        def _asset() -> int:
            time.sleep(sleep)
            return 1

        return _asset

    @dg.multi_asset(outs={"associations": dg.AssetOut(group_name="sequence"),
                          "skeletons3d": dg.AssetOut(group_name="sequence")},
                    partitions_def=SEQUENCES, deps=["extrinsics"])
    def association():
        time.sleep(0.05)
        return 1, 2

    return [
        step("raw_detections", []), step("gt_cameras", []), step("detections", ["raw_detections"], sleep=0.05),
        step("extrinsics", ["detections"]), association,
        step("metric_tables", ["associations", "skeletons3d", "gt_cameras"]),
        step("method_tables", ["extrinsics", "gt_cameras"], group="benchmark"),
    ]


def test_graph_and_path_come_from_the_asset_specs():
    specs = [spec for a in _toy_assets() for spec in a.specs]
    graph = timed_graph(specs)
    assert graph.assets.index("raw_detections") < graph.assets.index("detections") < graph.assets.index("metric_tables")
    assert "method_tables" in graph.assets  # partitioned by sequence, though in another group
    assert graph.path == {"detections", "extrinsics", "associations", "skeletons3d", "metric_tables"}


def test_timings_of_the_latest_materializations_and_their_total():
    assets = _toy_assets()
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions(SEQUENCES.name, ["toy__a", "toy__b"])
    resources = {"io_manager": dg.mem_io_manager}
    assert dg.materialize(assets, partition_key="toy__a", instance=instance, resources=resources).success
    # toy__b: no metric_tables, so no timings
    assert dg.materialize(assets, partition_key="toy__b", instance=instance, resources=resources,
                          selection=["raw_detections"]).success
    graph = timed_graph([spec for a in assets for spec in a.specs])
    table = stage_timings_table(instance, graph)
    assert set(table["sequence"]) == {"toy__a"}
    seconds = table.set_index("asset")["seconds"]
    assert set(seconds.index) == {*graph.assets, "total"}
    assert seconds["detections"] >= 0.05 and seconds["associations"] == seconds["skeletons3d"]
    steps = table[table["asset"].isin(graph.path)].drop_duplicates(["run_id", "step"])
    assert np.isclose(seconds["total"], steps["seconds"].sum())  # the association's step counted once
    assert seconds["total"] < seconds[["detections", "extrinsics", "associations", "metric_tables",
                                       "raw_detections", "gt_cameras", "method_tables"]].sum()
    assert table.loc[table["asset"] == "metric_tables", "step"].item() == "metric_tables"
    assert table["materialized_at"].notna().sum() == len(graph.assets)

    timings = build_stage_timings_asset([spec for a in assets for spec in a.specs])
    result = dg.materialize([timings], instance=instance, resources=resources)
    assert result.success
    stored = result.output_for_node("stage_timings")
    assert isinstance(stored, pd.DataFrame) and stored["seconds"].iloc[-1] == seconds["total"]
    metadata = result.get_asset_materialization_events()[0].materialization.metadata
    assert "toy__a" in metadata["summary"].value and metadata["skipped"].value == "toy__b"


def test_a_path_asset_without_a_recorded_time_leaves_the_total_blank():
    assets = _toy_assets()
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions(SEQUENCES.name, ["toy__a"])
    instance.report_runless_asset_event(dg.AssetMaterialization("metric_tables", partition="toy__a"))
    table = stage_timings_table(instance, timed_graph([spec for a in assets for spec in a.specs]))
    assert table["asset"].tolist() == ["metric_tables", "total"]
    assert table["seconds"].isna().all()
