"""The per-sequence calibration assets (intrinsics, extrinsics, their checks) and the metric table, run by
Dagster on a synthetic sequence whose ``detections`` artifact holds stand-in lifted poses (ground truth plus
the noise of the oracle ``evaluation.oracle``), so that the test does not depend on a trained lifter."""

import dagster as dg
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from evaluation.oracle import stand_in_lifted_poses
from humancal.lifter import LiftedPoses, R_crop_from_cam, lifted_to_table, normalize_detections
from humancal.synthetic import generate_scene, preset
from humancal.tables.schemas import to_arrow
from pipelines.definitions import build_definitions
from pipelines.partitions import SEQUENCES
from resources.datasets import DatasetsResource
from resources.io_managers import partition_path

PARTITION = "synthetic__calib"
SCENE = {"preset": "demo", "seed": 11, "num_people": 3, "num_views": 4, "num_frames": 60}
QUICK_FIT = {"iterations_3d": 40, "iterations_global": 2, "iterations_body": 3, "iterations_cameras": 2}
"""The body fits of the graph, cut short: these tests are about the calibration (``test_association_assets`` and
``tests/humancal/fitting`` check the fits)."""


def _stand_in_table(scene) -> pd.DataFrame:
    """The ``lifted_detections`` table of the stand-in poses, turned into each detection's crop frame."""
    stand_in = stand_in_lifted_poses(scene, np.random.default_rng(0))
    dense, lifted = stand_in.detections, stand_in.lifted
    norm = normalize_detections(dense.keypoints_px, dense.scores)
    K = np.stack([np.array([[r.fx_px, 0, r.cx_px], [0, r.fy_px, r.cy_px], [0, 0, 1.0]])
                  for r in scene.cameras.sort_values("view").itertuples()])[dense.view]
    crop = np.einsum("dij,dkj->dki", R_crop_from_cam(norm.box_centre_px, K), lifted.joints_cam_m)
    valid = lifted.valid & norm.valid
    crop[~valid] = np.nan
    return lifted_to_table(PARTITION, dense, LiftedPoses(crop, lifted.height_m, lifted.upright_score, valid,
                                                         norm.box_centre_px, "crop"))


@pytest.fixture(scope="module")
def materialized(tmp_path_factory, body_model):
    config = tmp_path_factory.mktemp("config") / "datasets.yaml"
    options = ", ".join(f"{k}: {v}" for k, v in SCENE.items())
    config.write_text(f"datasets:\n  synthetic:\n    kind: synthetic\n    sequences:\n      calib: {{{options}}}\n")
    storage = str(tmp_path_factory.mktemp("artifacts"))
    defs = build_definitions(storage, datasets=DatasetsResource(config_path=str(config)))
    scene_config = {k: v for k, v in SCENE.items() if k != "preset"}
    table = _stand_in_table(generate_scene(preset(SCENE["preset"], **scene_config), body_model, sequence="calib"))
    path = partition_path(storage, "detections", PARTITION)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(to_arrow(table, "lifted_detections"), str(path))
    graph = defs.resolve_asset_graph()
    keys = [k for k in graph.materializable_asset_keys
            if graph.get(k).partitions_def == SEQUENCES and k != dg.AssetKey("detections")
            and k != dg.AssetKey("method_tables")]  # on request: several full fits (test_association_assets)
    with dg.instance_for_test(temp_dir=str(tmp_path_factory.mktemp("home"))) as instance:
        instance.add_dynamic_partitions(SEQUENCES.name, [PARTITION])
        # the shared input of the body fit (unpartitioned: its own run)
        dg.materialize(assets=list(defs.assets), resources=defs.resources, instance=instance,
                       selection=dg.AssetSelection.assets("motion_prior_checkpoint"))
        result = dg.materialize(assets=list(defs.assets), resources=defs.resources,
                                selection=dg.AssetSelection.assets(*keys), partition_key=PARTITION, instance=instance,
                                run_config={"ops": {"body_fit": {"config": QUICK_FIT},
                                                    "metric_tables": {"config": QUICK_FIT}}})
    return result, storage


def _read(storage, asset):
    return pd.read_parquet(str(partition_path(storage, asset, PARTITION)))


def test_checks_pass_on_a_good_rig(materialized):
    result, _ = materialized
    assert result.success
    checks = {(e.asset_key.to_user_string(), e.check_name): e for e in result.get_asset_check_evaluations()}
    for key in [("intrinsics", "enough_upright_people"), ("extrinsics", "cameras_valid"),
                ("extrinsics", "focal_plausible"), ("extrinsics", "rig_geometry"), ("extrinsics", "focal_constrained")]:
        assert checks[key].passed, (key, checks[key].description)
        assert checks[key].metadata["checked"].value == 4, key
    size = checks[("extrinsics", "people_plausible")]
    assert size.passed and 0.8 < size.metadata["body_size_ratio"].value < 1.25, size.description
    floor = checks[("extrinsics", "floor_found")]
    # the standing people's sole plane, or their plumb lines when the plane is not trusted (with the groups found
    # again after the first bundle adjustment this scene takes the plumb lines, up within 0.2 deg)
    assert floor.passed and ("up from floor_plane" in floor.description or "up from plumb_lines" in floor.description), \
        floor.description


def test_a_check_with_nothing_to_check_warns_instead_of_passing(materialized):
    # every single-view focal of this scene is ill-conditioned (cameras near level): nothing to check there
    result, storage = materialized
    assert (_read(storage, "intrinsics")["status"] != "ok").all()
    check = {e.check_name: e for e in result.get_asset_check_evaluations()
             if e.asset_key.to_user_string() == "intrinsics"}["focal_plausible"]
    assert not check.passed and check.severity == dg.AssetCheckSeverity.WARN
    assert check.description.startswith("not checked: every view's single-view focal is flagged")
    assert check.metadata["checked"].value == 0


def test_intrinsics_table_has_diagnostics(materialized):
    table = _read(materialized[1], "intrinsics")
    assert list(table["view"]) == [0, 1, 2, 3]
    assert (table["num_inliers"] > 0).all() and (table["num_inliers"] <= table["num_candidates"]).all()
    assert set(table["status"]) <= {"ok", "ill_conditioned", "no_upright"}
    assert table["tilt_deg"].between(-90, 90).all()


def test_metric_rows_of_the_initialisation_and_the_lifter(materialized):
    metrics = _read(materialized[1], "metric_tables")
    init = metrics[(metrics["method"] == "init") & metrics["view"].isna()].set_index("metric")["value"]
    assert init["focal_error_pct"] < 2.0
    assert init["angle_error_deg"] < 1.0
    assert init["position_error_mm"] < 100.0
    assert init["reprojection_error_px"] < 2.0 * init["reprojection_error_gt_cameras_px"]
    per_view = metrics[(metrics["method"] == "init") & (metrics["metric"] == "focal_error_pct")]
    assert sorted(per_view["view"].dropna()) == [0, 1, 2, 3]
    assert not metrics["metric"].str.contains("view_").any()
    lifter = metrics[(metrics["method"] == "lifter") & metrics["view"].isna()].set_index("metric")["value"]
    # the stand-in has 50 mm joint noise and 3 deg pose rotations
    assert 20.0 < lifter["mpjpe_mm"] < 120.0 and lifter["pa_mpjpe_mm"] < lifter["mpjpe_mm"]


def test_rig_pictures_are_attached(materialized):
    result, _ = materialized
    events = {e.materialization.asset_key.to_user_string(): e.materialization for e in
              result.get_asset_materialization_events()}
    assert events["extrinsics"].metadata["rig"].value.startswith("![estimated rig](data:image/png;base64,")
    assert events["metric_tables"].metadata["rigs"].value.startswith("![camera rigs](data:image/png;base64,")
