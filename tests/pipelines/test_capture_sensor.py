"""The capture inbox sensor: a dropped folder is registered and calibrated; an invalid one is skipped once."""

import json
from pathlib import Path

import dagster as dg
import numpy as np
import yaml

from humancal.formats.skeletons import SKELETONS
from pipelines.sensors import build_capture_inbox_sensor

BODY25 = SKELETONS["body25"]


def _drop(inbox: Path, name: str, capture: dict | None, frames: int = 3) -> Path:
    folder = inbox / name
    for v, view in enumerate(("cam1", "cam2")):
        flat = np.zeros((25, 3))  # each camera sees the person elsewhere (identical views are refused as copies)
        flat[BODY25.index("nose")] = (100.0 + 7 * v, 50.0, 0.9)
        flat[BODY25.index("left_ankle")] = (100.0 + 7 * v, 250.0, 0.8)
        (folder / view).mkdir(parents=True)
        for f in range(frames):
            people = [{"pose_keypoints_2d": flat.ravel().tolist()}]
            (folder / view / f"{view}_{f:012d}_keypoints.json").write_text(json.dumps({"people": people}))
    if capture is not None:
        (folder / "capture.yaml").write_text(yaml.safe_dump(capture))
    return folder


def _tick(sensor, instance, cursor):
    context = dg.build_sensor_context(instance=instance, cursor=cursor)
    return sensor(context)


def test_inbox_registers_valid_drops_and_skips_invalid_ones_once(tmp_path, monkeypatch, capfd):
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path / "state"))
    inbox, user_file = tmp_path / "inbox", tmp_path / "state" / "datasets.yaml"
    sensor = build_capture_inbox_sensor(inbox=inbox, user_datasets=user_file)
    instance = dg.DagsterInstance.ephemeral()

    empty = _tick(sensor, instance, None)
    assert empty.run_requests == [] and empty.dynamic_partitions_requests == []

    _drop(inbox, "studio", {"format": "openpose", "image_size": [640, 480], "skeleton": "body25"})
    _drop(inbox, "noskeleton", {"format": "openpose", "image_size": [640, 480]})
    _drop(inbox, "copying", None)  # no capture.yaml yet: not looked at
    capfd.readouterr()
    result = _tick(sensor, instance, None)
    log = capfd.readouterr().err  # the sensor's log
    assert [r.partition_key for r in result.run_requests] == ["studio__capture"]
    assert result.dynamic_partitions_requests[0].partition_keys == ["studio__capture"]
    assert "skipped" in log and "noskeleton" in log and "--skeleton" in log
    assert "cam1_000000000000_keypoints.json" in log and "copying" not in log
    entry = yaml.safe_load(user_file.read_text())["datasets"]
    assert list(entry) == ["studio"]
    assert entry["studio"]["sequences"]["capture"]["views"] == [str(inbox / "studio" / "cam1"),
                                                                 str(inbox / "studio" / "cam2")]
    cursor = json.loads(result.cursor)
    assert set(cursor) == {"studio", "noskeleton"}

    again = _tick(sensor, instance, result.cursor)  # the next tick looks at neither again
    assert again.run_requests == [] and "noskeleton" not in capfd.readouterr().err

    fixed = yaml.safe_load((inbox / "noskeleton" / "capture.yaml").read_text()) | {"skeleton": "body25", "fps": 25}
    (inbox / "noskeleton" / "capture.yaml").write_text(yaml.safe_dump(fixed))  # a change: looked at again
    retried = _tick(sensor, instance, again.cursor)
    assert [r.partition_key for r in retried.run_requests] == ["noskeleton__capture"]
    assert set(yaml.safe_load(user_file.read_text())["datasets"]) == {"studio", "noskeleton"}


def test_the_sensor_is_in_the_definitions():
    from pipelines.definitions import defs

    sensor = defs.get_sensor_def("capture_inbox")
    assert sensor.asset_selection is not None
