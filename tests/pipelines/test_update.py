"""`humancal update` semantics on the real graph: synthetic__tiny, and the lifter trained (tiny config) on a
four-clip subset of the CMU mocap.

Materialize what is missing; a second update does nothing; a code change that alters an asset's output
recomputes that asset and its downstream only; a code change that reproduces the same data recomputes only
that asset; a lifter trained with another configuration gets another data version and the detections are
lifted again, and training the first configuration again reproduces its data version.

The camera initialisation (``extrinsics``) and the metric table are left out here: a lifter trained for seconds
cannot calibrate cameras. They run on stand-in lifted poses in ``test_calibration_assets.py``.
"""

import dagster as dg
import pytest
from dagster._core.definitions.data_version import DATA_VERSION_TAG

from assets.baselines import gt_camera_triangulation
from assets.common import UPDATE_CONDITION, table_metadata, table_output
from assets.sequence_inputs import sequence_inputs
from humancal.baselines import TriangulationConfig, triangulate_identified
from humancal.camera import cameras_from_table
from humancal.lifter import LifterConfig
from humancal.settings import DataRootError, dataset_dir
from pipelines.definitions import build_definitions
from pipelines.partitions import SEQUENCES
from pipelines.update import update
from resources.datasets import DatasetsResource

PARTITION = "synthetic__tiny"
CLIPS = ("01/01_01", "07/07_01", "02/02_01", "14/14_04")
"""Two training subjects and the two held-out ones."""
LEFT_OUT = [dg.AssetKey("extrinsics")]
SEQUENCE_INPUTS = ["raw_detections", "views", "gt_cameras", "gt_poses3d", "gt_associations", "gt_people"]


@pytest.fixture(scope="module")
def data_root(tmp_path_factory):
    try:
        bvh = dataset_dir("cmu_mocap", required_for="the lifter in the update tests") / "bvh_daz"
    except DataRootError as err:
        pytest.skip(str(err))
    root = tmp_path_factory.mktemp("data")
    for clip in CLIPS:
        subject, name = clip.split("/")
        (root / "cmu_mocap" / "bvh_daz" / subject).mkdir(parents=True, exist_ok=True)
        (root / "cmu_mocap" / "bvh_daz" / subject / f"{name}.bvh.gz").symlink_to(bvh / subject / f"{name}.bvh.gz")
    return root


@pytest.fixture(scope="module")
def instance(tmp_path_factory):
    with dg.instance_for_test(temp_dir=str(tmp_path_factory.mktemp("dagster_home"))) as inst:
        inst.add_dynamic_partitions(SEQUENCES.name, [PARTITION])
        yield inst


@pytest.fixture(scope="module")
def storage(tmp_path_factory):
    return str(tmp_path_factory.mktemp("artifacts"))


@pytest.fixture(scope="module")
def make_defs(storage, data_root):
    def make(seed: int = 0):
        return build_definitions(storage, LifterConfig.tiny(seed=seed), DatasetsResource(data_dir=str(data_root)))

    return make


def _update(defs, instance):
    return update(defs, instance, partitions=[PARTITION], exclude=LEFT_OUT)


def _with(defs, *replacements):
    keys = {k for r in replacements for k in r.keys}
    kept = [a for a in defs.assets if not (set(a.keys) & keys)]
    return dg.Definitions(assets=[*kept, *replacements], resources=defs.resources)


def _names(result):
    return sorted(name for name, _ in result.materialized)


def _data_version(instance, name):
    record = instance.get_latest_data_version_record(dg.AssetKey(name))
    return record.asset_materialization.tags[DATA_VERSION_TAG]


def test_update_materializes_missing_then_nothing(instance, make_defs):
    first = _update(make_defs(), instance)
    assert _names(first) == sorted(
        ["mocap_clips", "lifter_checkpoint", *SEQUENCE_INPUTS, "gt_camera_triangulation", "detections", "intrinsics"]
    )
    assert ("mocap_clips", None) in first.materialized and ("lifter_checkpoint", None) in first.materialized
    assert all(pk == PARTITION for name, pk in first.materialized if not name.startswith(("mocap", "lifter")))
    # the shared inputs come first
    order = [name for name, _ in first.materialized]
    assert order.index("lifter_checkpoint") < order.index("detections") < order.index("intrinsics")
    assert _update(make_defs(), instance).count == 0


def test_lifter_config_change_relifts_and_same_config_reproduces_the_checkpoint(instance, make_defs):
    _update(make_defs(), instance)
    original = _data_version(instance, "lifter_checkpoint")
    changed = _update(make_defs(seed=1), instance)
    assert _names(changed) == ["detections", "intrinsics", "lifter_checkpoint"]
    assert _data_version(instance, "lifter_checkpoint") != original
    back = _update(make_defs(seed=0), instance)
    assert "lifter_checkpoint" in _names(back) and "mocap_clips" not in _names(back)
    assert _data_version(instance, "lifter_checkpoint") == original  # deterministic training
    assert _update(make_defs(seed=0), instance).count == 0


def test_code_change_with_new_output_recomputes_it_and_downstream_only(instance, make_defs):
    @dg.asset(
        name="gt_camera_triangulation", partitions_def=SEQUENCES, group_name="sequence",
        metadata=table_metadata("poses3d"), code_version="2-no-outlier-pass", automation_condition=UPDATE_CONDITION,
    )
    def changed(raw_detections, gt_cameras, gt_associations) -> dg.Output:
        cfg = TriangulationConfig(outlier_threshold_px=None)
        poses = triangulate_identified(raw_detections, gt_associations, cameras_from_table(gt_cameras), "tiny", cfg)
        return table_output(poses, "poses3d")

    defs = make_defs()
    _update(defs, instance)  # make sure the baseline state exists
    # metric_tables (downstream) is left out with extrinsics here; excluding it checks the descendant rule
    result = _update(_with(defs, changed), instance)
    assert _names(result) == ["gt_camera_triangulation"]
    assert _update(_with(defs, changed), instance).count == 0


def test_code_bump_with_identical_output_stops_at_that_asset(instance, make_defs):
    defs = make_defs()
    _update(defs, instance)
    bumped = sequence_inputs.map_asset_specs(lambda spec: spec.replace_attributes(code_version="1-bumped"))
    result = _update(_with(defs, bumped), instance)
    assert _names(result) == sorted(SEQUENCE_INPUTS)
    assert _update(_with(defs, bumped), instance).count == 0


def test_a_failing_asset_is_reported_and_only_its_descendants_are_left_out(instance, make_defs):
    @dg.asset(
        name="detections", partitions_def=SEQUENCES, group_name="sequence",
        metadata=table_metadata("lifted_detections"), code_version="broken", automation_condition=UPDATE_CONDITION,
    )
    def broken(raw_detections, lifter_checkpoint) -> dg.Output:
        raise ValueError("lifter exploded")

    bumped = sequence_inputs.map_asset_specs(lambda spec: spec.replace_attributes(code_version="2-bumped"))
    result = _update(_with(make_defs(), broken, bumped), instance)
    assert [(name, pk) for name, pk, _ in result.failed] == [("detections", PARTITION)]
    assert "ValueError: lifter exploded" in result.failed[0][2]
    assert "intrinsics" not in _names(result)  # downstream of the failure
    assert set(SEQUENCE_INPUTS) <= set(_names(result))  # the rest of the partition went on
