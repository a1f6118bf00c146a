"""`humancal update` semantics on the real graph, on the small synthetic__tiny sequence.

Materialize what is missing; a second update does nothing; a code change that alters an asset's
output recomputes that asset and its downstream only; a code change that reproduces the same data
recomputes only that asset.
"""

import dagster as dg
import pytest

from assets.baselines import gt_camera_triangulation
from assets.common import UPDATE_CONDITION, table_metadata, table_output
from assets.sequence_inputs import sequence_inputs
from humancal.baselines import TriangulationConfig, triangulate_identified
from humancal.camera import cameras_from_table
from pipelines.definitions import build_definitions
from pipelines.partitions import SEQUENCES
from pipelines.update import update

PARTITION = "synthetic__tiny"


@pytest.fixture(scope="module")
def instance(tmp_path_factory):
    with dg.instance_for_test(temp_dir=str(tmp_path_factory.mktemp("dagster_home"))) as inst:
        inst.add_dynamic_partitions(SEQUENCES.name, [PARTITION])
        yield inst


@pytest.fixture(scope="module")
def storage(tmp_path_factory):
    return str(tmp_path_factory.mktemp("artifacts"))


def _with(defs, *replacements):
    keys = {k for r in replacements for k in r.keys}
    kept = [a for a in defs.assets if not (set(a.keys) & keys)]
    return dg.Definitions(assets=[*kept, *replacements], resources=defs.resources)


def _names(result):
    return sorted(name for name, _ in result.materialized)


def test_update_materializes_missing_then_nothing(instance, storage):
    defs = build_definitions(storage)
    first = update(defs, instance, partitions=[PARTITION])
    assert _names(first) == sorted(
        ["raw_detections", "views", "gt_cameras", "gt_poses3d", "gt_associations", "gt_people",
         "gt_camera_triangulation", "metric_tables"]
    )
    assert all(pk == PARTITION for _, pk in first.materialized)
    second = update(defs, instance, partitions=[PARTITION])
    assert second.count == 0


def test_code_change_with_new_output_recomputes_it_and_downstream_only(instance, storage):
    @dg.asset(
        name="gt_camera_triangulation", partitions_def=SEQUENCES, group_name="sequence",
        metadata=table_metadata("poses3d"), code_version="2-no-outlier-pass", automation_condition=UPDATE_CONDITION,
    )
    def changed(raw_detections, gt_cameras, gt_associations) -> dg.Output:
        cfg = TriangulationConfig(outlier_threshold_px=None)
        poses = triangulate_identified(raw_detections, gt_associations, cameras_from_table(gt_cameras), "tiny", cfg)
        return table_output(poses, "poses3d")

    defs = build_definitions(storage)
    update(defs, instance, partitions=[PARTITION])  # make sure the baseline state exists
    result = update(_with(defs, changed), instance, partitions=[PARTITION])
    assert _names(result) == ["gt_camera_triangulation", "metric_tables"]
    assert update(_with(defs, changed), instance, partitions=[PARTITION]).count == 0


def test_code_bump_with_identical_output_stops_at_that_asset(instance, storage):
    defs = build_definitions(storage)
    update(defs, instance, partitions=[PARTITION])
    bumped = sequence_inputs.map_asset_specs(lambda spec: spec.replace_attributes(code_version="1-bumped"))
    result = update(_with(defs, bumped), instance, partitions=[PARTITION])
    assert _names(result) == sorted(["raw_detections", "views", "gt_cameras", "gt_poses3d", "gt_associations", "gt_people"])
    assert update(_with(defs, bumped), instance, partitions=[PARTITION]).count == 0
