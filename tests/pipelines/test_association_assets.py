"""The association assets (``associations``, ``skeletons3d``) and their metric rows, run by Dagster on a
synthetic sequence. To stay fast the calibration is not run: the ``detections`` artifact holds stand-in lifted
poses (as in ``test_calibration_assets``) and the ``extrinsics`` artifact the true cameras."""

import dagster as dg
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from evaluation.association_metrics import identity_metrics
from humancal.synthetic import generate_scene, preset
from humancal.tables.schemas import SCHEMAS, to_arrow
from pipelines.definitions import build_definitions
from pipelines.partitions import SEQUENCES
from resources.datasets import DatasetsResource
from resources.io_managers import partition_path
from tests.pipelines.test_calibration_assets import SCENE, _stand_in_table

PARTITION = "synthetic__calib"
ASSETS = ["raw_detections", "views", "gt_cameras", "gt_poses3d", "gt_associations", "gt_people", "gt_motions",
          "gt_camera_triangulation", "gt_camera_associations", "gt_camera_skeletons3d", "associations", "skeletons3d",
          "fitted_motions", "refined_cameras", "run_records", "metric_tables", "method_tables"]
FIT = {"iterations_3d": 150, "iterations_global": 5, "iterations_body": 10, "iterations_cameras": 5}
METHODS = ["separate", "int_ext_no_bundle", "no_prior"]
"""A shorter fit than the default (the test checks the wiring and sane figures; ``tests/humancal/fitting`` and
``scripts/body_sweep.py`` measure the fit itself)."""


def _write(storage, asset, table, name):
    path = partition_path(storage, asset, PARTITION)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(to_arrow(table, name), str(path))


@pytest.fixture(scope="module")
def materialized(tmp_path_factory, body_model):
    config = tmp_path_factory.mktemp("config") / "datasets.yaml"
    options = ", ".join(f"{k}: {v}" for k, v in SCENE.items())
    config.write_text(f"datasets:\n  synthetic:\n    kind: synthetic\n    sequences:\n      calib: {{{options}}}\n")
    storage = str(tmp_path_factory.mktemp("artifacts"))
    defs = build_definitions(storage, datasets=DatasetsResource(config_path=str(config)))
    scene = generate_scene(preset(SCENE["preset"], **{k: v for k, v in SCENE.items() if k != "preset"}), body_model,
                           sequence="calib")
    _write(storage, "detections", _stand_in_table(scene), "lifted_detections")
    _write(storage, "extrinsics", scene.cameras.assign(sequence=PARTITION), "cameras")
    with dg.instance_for_test(temp_dir=str(tmp_path_factory.mktemp("home"))) as instance:
        instance.add_dynamic_partitions(SEQUENCES.name, [PARTITION])
        # the shared input of the body fit (unpartitioned: its own run)
        dg.materialize(assets=list(defs.assets), resources=defs.resources, instance=instance,
                       selection=dg.AssetSelection.assets("motion_prior_checkpoint"))
        result = dg.materialize(assets=list(defs.assets), resources=defs.resources,
                                selection=dg.AssetSelection.assets(*ASSETS), partition_key=PARTITION,
                                instance=instance, run_config={"ops": {
                                    "body_fit": {"config": FIT}, "metric_tables": {"config": FIT},
                                    "method_tables": {"config": {**FIT, "methods": [*METHODS, "convention_floor"]}}}})
    return result, storage, scene, defs


def _read(storage, asset):
    return pd.read_parquet(str(partition_path(storage, asset, PARTITION)))


def test_the_self_calibrated_association_reads_no_ground_truth(materialized):
    graph = materialized[3].resolve_asset_graph()
    for key in ("associations", "skeletons3d"):
        parents = {k.to_user_string() for k in graph.get(dg.AssetKey(key)).parent_keys}
        assert parents == {"detections", "extrinsics"}, key
    assert "associations" in {k.to_user_string() for k in graph.asset_keys_for_group("sequence")}


def test_association_tables(materialized):
    result, storage, scene, _ = materialized
    assert result.success
    people = _read(storage, "associations")
    assert list(people.columns) == SCHEMAS["associations"].names
    assert people.groupby(["frame", "view", "det_id"]).ngroups == len(people) == len(scene.associations)
    assert people["person_id"].max() + 1 == SCENE["num_people"]
    skeletons = _read(storage, "skeletons3d")
    assert list(skeletons.columns) == SCHEMAS["skeletons3d"].names
    triangulated = skeletons["valid"] & (skeletons["num_views"] > 0)  # the others: filled over time
    assert skeletons["valid"].mean() > 0.9 and (skeletons.loc[triangulated, "num_views"] >= 2).all()
    assert triangulated.mean() > 0.9
    meta = {e.materialization.asset_key.to_user_string(): e.materialization.metadata
            for e in result.get_asset_materialization_events()}["associations"]
    assert meta["num_people"].value == SCENE["num_people"] and meta["rows"].value == len(people)
    assert 0 < meta["seconds_total"].value < 60 and "seconds_matching" in meta
    assert meta["picture"].value.startswith("![person ids over time") and "base64," in meta["picture"].value


def test_association_metric_rows(materialized):
    metrics = _read(materialized[1], "metric_tables")
    for method in ("association", "epipolar_only", "association_gt_cameras", "epipolar_only_gt_cameras"):
        rows = metrics[metrics["method"] == method].set_index("metric")["value"]
        assert set(rows.index) == {"pairwise_precision", "pairwise_recall", "pairwise_f1", "id_switches", "idf1",
                                   "fp_rejection_rate", "num_people_error", "mpjpe_mm", "pcp_avg", "seconds",
                                   "pcp_avg_sequence_aligned", "mpjpe_sequence_aligned_mm"}, method
        assert rows["pairwise_f1"] > 0.9 and rows["pairwise_precision"] > 0.9, (method, rows.to_dict())
        assert rows["num_people_error"] == 0 and rows["id_switches"] <= 2, (method, rows.to_dict())
        assert rows["mpjpe_mm"] < 100 and rows["pcp_avg"] > 80, (method, rows.to_dict())
        # one least-squares similarity for the whole sequence: the mean joint error stays about the same or drops
        assert rows["mpjpe_sequence_aligned_mm"] <= 1.05 * rows["mpjpe_mm"], (method, rows.to_dict())
        assert 0 < rows["seconds"] < 60
    # the ground-truth camera rows are not figures of the estimated cameras: no failed-checks mark
    assert metrics.loc[metrics["method"] == "association_gt_cameras", "failed_checks"].isna().all()


def test_run_records_hand_the_stages_seconds_and_checks_to_the_metric_tables(materialized):
    """The seconds in the metric tables are those the stages recorded, read once by ``run_records`` (an input of
    the metric assets, which read no instance); extrinsics written outside the graph have no recorded checks."""
    result, storage, _, defs = materialized
    graph = defs.resolve_asset_graph()
    for table in ("metric_tables", "method_tables"):
        assert dg.AssetKey("run_records") in graph.get(dg.AssetKey(table)).parent_keys, table
    meta = {e.materialization.asset_key.to_user_string(): e.materialization.metadata
            for e in result.get_asset_materialization_events()}
    records = _read(storage, "run_records").set_index("asset")
    assert list(records.index) == ["extrinsics", "associations", "gt_camera_associations", "fitted_motions"]
    assert records.loc["extrinsics", "failed_checks"] == "unchecked"
    metrics = _read(storage, "metric_tables")
    for asset, method in (("associations", "association"), ("gt_camera_associations", "association_gt_cameras"),
                          ("fitted_motions", "int_ext")):
        seconds = records.loc[asset, "seconds"]
        assert seconds == pytest.approx(meta[asset]["seconds_total"].value) and seconds > 0, asset
        assert records.loc[asset, "run_id"] == result.run_id, asset
        row = metrics[(metrics["method"] == method) & (metrics["metric"] == "seconds") & metrics["view"].isna()]
        assert row["value"].item() == pytest.approx(seconds), method
    assert (metrics.loc[metrics["method"] == "int_ext", "failed_checks"].dropna() == "unchecked").all()


def test_fitted_motions_and_body_metric_rows(materialized):
    result, storage, scene, defs = materialized
    graph = defs.resolve_asset_graph()
    parents = {k.to_user_string() for k in graph.get(dg.AssetKey("fitted_motions")).parent_keys}
    # never ground truth; the prior through the graph (lineage)
    assert parents == {"detections", "associations", "skeletons3d", "extrinsics", "motion_prior_checkpoint"}
    assert graph.get(dg.AssetKey("refined_cameras")).parent_keys == graph.get(dg.AssetKey("fitted_motions")).parent_keys
    motions = _read(storage, "fitted_motions")
    assert list(motions.columns) == SCHEMAS["motions"].names
    assert motions["person_id"].nunique() == SCENE["num_people"]
    assert motions.groupby("person_id")["frame"].nunique().min() > 0.9 * SCENE["num_frames"]
    meta = {e.materialization.asset_key.to_user_string(): e.materialization.metadata
            for e in result.get_asset_materialization_events()}["fitted_motions"]
    assert 0 < meta["seconds_total"].value < 120 and "seconds_fit3d" in meta and "loss_reprojection" in meta
    assert meta["reprojection"].value.startswith("![fitted meshes reprojected") and "base64," in meta["scene"].value
    assert meta["reprojection_error_px"].value < 15
    metrics = _read(storage, "metric_tables")
    methods = _read(storage, "method_tables")
    assert set(methods["method"]) == {*METHODS, "convention_floor"}
    # the synthetic cameras have centred principal points and square pixels: the convention costs them nothing
    floor = methods[(methods["method"] == "convention_floor") & methods["view"].isna()].set_index("metric")["value"]
    assert floor["angle_error_deg"] < 1e-3 and floor["focal_error_pct"] < 1e-3, floor.to_dict()
    assert "reprojection_error_px" in floor.index and "mpjpe_mm" not in floor.index
    both = pd.concat([metrics, methods], ignore_index=True)
    both = both[both["view"].isna()]
    expected = {"mpjpe_mm", "pa_mpjpe_mm", "pcp_avg", "accel_error_mm_s2", "pve_mm", "fit_reprojection_error_px",
                "seconds"}
    cameras = {"focal_error_pct", "position_error_mm", "angle_error_deg", "reprojection_error_px"}
    for method in ("int_ext", *METHODS):
        rows = both[both["method"] == method].set_index("metric")["value"]
        assert expected | cameras <= set(rows.index), (method, sorted(rows.index))
        assert rows["mpjpe_mm"] < 60 and rows["pve_mm"] < 120 and rows["pcp_avg"] > 80, (method, rows.to_dict())
    # the extrinsics here are the true cameras: the refinement keeps them close (few pixels of detector noise)
    refined = both[both["method"] == "int_ext"].set_index("metric")["value"]
    assert refined["focal_error_pct"] < 2 and refined["angle_error_deg"] < 0.5, refined.to_dict()
    meta = {e.materialization.asset_key.to_user_string(): e.materialization.metadata
            for e in result.get_asset_materialization_events()}["refined_cameras"]
    assert meta["regime"].value == "int_ext" and meta["focal_change_pct"].value < 2
    for method in ("skeletons3d", "skeletons3d_gt_cameras"):
        rows = metrics[metrics["method"] == method].set_index("metric")["value"]
        assert {"mpjpe_mm", "pa_mpjpe_mm", "accel_error_mm_s2"} <= set(rows.index)
    # the dynamics prior is smoother than raw joint angles fitted with no prior
    accel = both[both["metric"] == "accel_error_mm_s2"].set_index("method")["value"]
    assert accel["int_ext"] < accel["no_prior"]


def test_identity_metrics_count_pairs_switches_and_rejections():
    truth = pd.DataFrame({"sequence": "s", "frame": [0, 0, 0, 0, 1, 1, 1],
                          "view": [0, 1, 2, 0, 0, 1, 2], "det_id": [0, 0, 0, 1, 0, 0, 0],
                          "person_id": [0, 0, 0, -1, 0, 0, -1]})
    # frame 0: person 0 split into {view 0, view 1} + {view 2}; the false positive kept; frame 1: a new id
    estimated = truth.assign(person_id=[0, 0, 1, 2, 3, 3, -1])
    rows = {r.metric: r.value for r in identity_metrics(estimated, truth)}
    # true cross-view pairs: 3 (frame 0) + 1 (frame 1); estimated: 1 + 1, both right
    assert rows["pairwise_precision"] == 1.0 and rows["pairwise_recall"] == 0.5
    assert np.isclose(rows["pairwise_f1"], 2 / 3)
    assert rows["id_switches"] == 1 and rows["fp_rejection_rate"] == 50.0
    # ids 0 and 3 both hold 2 of person 0's 5 detections: one of them maps to it (IDTP 2); 6 estimated, 5 true
    assert np.isclose(rows["idf1"], 2 * 2 / (6 + 5))
    assert rows["num_people_error"] == 3  # ids 0, 1, 2, 3 for one person

    # partial truth (Shelf): unannotated detections are unknown, not false positives
    merged_with_unknown = truth.assign(person_id=[0, 0, 0, -1, 0, 0, -1])
    estimated = truth.assign(person_id=[0, 0, 0, 0, 1, 1, 1])  # an unannotated detection joins person 0
    partial = {r.metric: r.value for r in identity_metrics(estimated, merged_with_unknown, complete=False)}
    complete = {r.metric: r.value for r in identity_metrics(estimated, merged_with_unknown)}
    assert partial["pairwise_precision"] == 1.0 and complete["pairwise_precision"] < 1.0
    assert np.isnan(partial["fp_rejection_rate"]) and np.isnan(partial["num_people_error"])
