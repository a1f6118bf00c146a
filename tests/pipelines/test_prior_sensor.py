"""The mocap-change sensor and the weekly schedule of the motion prior, driven on a temporary data root."""

from __future__ import annotations

import dagster as dg

from pipelines.definitions import build_definitions
from pipelines.prior_automation import mocap_fingerprint
from resources.datasets import DatasetsResource


def _tick(sensor, root, cursor):
    context = dg.build_sensor_context(cursor=cursor, resources={"datasets": DatasetsResource(data_dir=str(root))})
    return sensor(context)


def _sensor(tmp_path):
    defs = build_definitions(storage_root=str(tmp_path / "artifacts"))
    return defs, defs.resolve_sensor_def("mocap_change_prior_retraining")


def test_a_new_clip_file_requests_one_retraining(tmp_path):
    folder = tmp_path / "data" / "cmu_mocap" / "bvh_daz" / "01"
    folder.mkdir(parents=True)
    (folder / "01_01.bvh.gz").write_bytes(b"first clip")
    defs, sensor = _sensor(tmp_path)
    assert sensor.default_status == dg.DefaultSensorStatus.STOPPED

    first = _tick(sensor, tmp_path / "data", None)
    assert not first.run_requests and first.cursor == mocap_fingerprint(tmp_path / "data") != ""

    (folder / "01_02.bvh.gz").write_bytes(b"a new clip")
    changed = _tick(sensor, tmp_path / "data", first.cursor)
    assert len(changed.run_requests) == 1 and changed.cursor != first.cursor
    request = changed.run_requests[0]
    assert request.partition_key == "motion_prior" and request.run_key == f"mocap-{changed.cursor}"
    assert {k.to_user_string() for k in request.asset_selection} == {"mocap_clips", "motion_prior_trained",
                                                                     "prior_metrics"}
    assert sensor.job_name == "prior_training"
    job = defs.resolve_job_def("prior_training")
    assert {k.to_user_string() for k in request.asset_selection} <= {k.to_user_string() for k in job.asset_layer.selected_asset_keys}

    unchanged = _tick(sensor, tmp_path / "data", changed.cursor)
    assert not unchanged.run_requests and unchanged.cursor == changed.cursor


def test_missing_mocap_requests_nothing(tmp_path):
    _, sensor = _sensor(tmp_path)
    result = _tick(sensor, tmp_path / "nothing here", "0123456789abcdef")
    assert not result.run_requests and result.cursor == ""
    assert "no mocap" in result.skip_reason.skip_message


def test_weekly_schedule_retrains_the_default_variant(tmp_path):
    defs = build_definitions(storage_root=str(tmp_path / "artifacts"))
    schedule = defs.resolve_schedule_def("weekly_prior_retraining")
    assert schedule.default_status == dg.DefaultScheduleStatus.STOPPED and schedule.job_name == "prior_training"
    request = schedule(dg.build_schedule_context())
    assert request.partition_key == "motion_prior"
