"""OpenPose JSON folders: reading, writing, round trip, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from humancal.formats import FormatError, read_detections, write_openpose
from humancal.formats.detections import sort_detections
from humancal.formats.detections.openpose import list_openpose_frames, read_openpose_file
from humancal.formats.skeletons import SKELETONS
from humancal.keypoints import CANONICAL_JOINTS

BODY25 = SKELETONS["body25"]


def _person(num_joints: int, present: dict[int, tuple[float, float, float]]) -> dict:
    flat = np.zeros((num_joints, 3))
    for j, xyc in present.items():
        flat[j] = xyc
    return {"person_id": [-1], "pose_keypoints_2d": flat.ravel().tolist()}


def _write_frame(folder: Path, frame: int, people: list[dict], name: str = "clip") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}_{frame:012d}_keypoints.json"
    path.write_text(json.dumps({"version": 1.3, "people": people}))
    return path


def _two_view_fixture(root: Path) -> list[Path]:
    """Views 0 and 1, frames 5 and 6; view 1 frame 6 is empty (no people)."""
    v0, v1 = root / "cam0", root / "cam1"
    nose, l_sho, r_heel = BODY25.index("nose"), BODY25.index("left_shoulder"), BODY25.index("right_heel")
    neck = BODY25.index("neck")
    people = [_person(25, {nose: (10.0, 20.0, 0.9), neck: (11, 30, 0.8)}), _person(25, {l_sho: (50.5, 60.25, 0.7)})]
    _write_frame(v0, 5, people)
    _write_frame(v0, 6, [_person(25, {r_heel: (5.0, 6.0, 0.4)})])
    _write_frame(v1, 5, [_person(25, {nose: (1.0, 2.0, 1.0)})])
    _write_frame(v1, 6, [])
    return [v0, v1]


def test_read_body25_folders_gives_one_row_per_present_canonical_joint(tmp_path):
    table = read_detections(_two_view_fixture(tmp_path), "openpose", sequence="s", image_size=(640, 480),
                            skeleton="body25")
    assert list(table.columns) == ["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"]
    columns = ["frame", "view", "det_id", "joint", "x_px", "y_px", "score"]
    got = [tuple(r) for r in table[columns].itertuples(index=False)]
    assert got == [
        (5, 0, 0, "nose", 10.0, 20.0, 0.9),  # the neck is not canonical: no row
        (5, 0, 1, "left_shoulder", 50.5, 60.25, 0.7),
        (5, 1, 0, "nose", 1.0, 2.0, 1.0),
        (6, 0, 0, "right_heel", 5.0, 6.0, 0.4),
    ]
    assert (table["sequence"] == "s").all()
    assert table.attrs["image_size_px"] == {0: (640, 480), 1: (640, 480)}


def test_empty_frame_is_valid_and_gives_no_rows(tmp_path):
    _write_frame(tmp_path / "v", 0, [])
    table = read_detections([tmp_path / "v"], "openpose", sequence="s", image_size=(640, 480))
    assert len(table) == 0 and list(table.columns)[0] == "sequence"


def test_coco18_is_recognised_by_length(tmp_path):
    coco18 = SKELETONS["coco18"]
    _write_frame(tmp_path / "v", 0, [_person(18, {coco18.index("right_hip"): (3.0, 4.0, 0.5)})])
    table = read_detections([tmp_path / "v"], "openpose", sequence="s", image_size=(640, 480))
    assert table["joint"].tolist() == ["right_hip"]
    people, skel = read_openpose_file(tmp_path / "v" / "clip_000000000000_keypoints.json")
    assert skel.name == "coco18" and people.shape == (1, 18, 3)


def test_frames_from_file_order_when_names_have_no_number(tmp_path):
    folder = tmp_path / "v"
    folder.mkdir()
    for name in ("b_keypoints.json", "a_keypoints.json"):
        (folder / name).write_text(json.dumps({"people": []}))
    assert [(f, p.name) for f, p in list_openpose_frames(folder)] == [(0, "a_keypoints.json"), (1, "b_keypoints.json")]
    with pytest.raises(FormatError, match="b_keypoints.json|a_keypoints.json"):
        list_openpose_frames(folder, frame_from="name_number")


def test_round_trip_body25(tmp_path, detections):
    folders = write_openpose(detections, tmp_path / "out")
    assert sorted(folders) == [0, 1]
    names = sorted(p.name for p in folders[1].iterdir())
    assert names == [f"demo_{f:012d}_keypoints.json" for f in (3, 4, 5, 6)]  # every frame between first and last
    back = read_detections(folders, "openpose", sequence="demo", image_size=(1920, 1080), skeleton="body25")
    pd.testing.assert_frame_equal(back, detections, check_exact=True)
    assert not list((tmp_path / "out").rglob("*.tmp"))


def test_written_body25_neck_is_the_shoulder_midpoint(tmp_path):
    rows = [
        ("s", 0, 0, 0, "left_shoulder", 10.0, 20.0, 0.9),
        ("s", 0, 0, 0, "right_shoulder", 30.0, 40.0, 0.6),
    ]
    table = pd.DataFrame(rows, columns=["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"])
    folder = write_openpose(table, tmp_path)[0]
    flat = json.loads((folder / "s_000000000000_keypoints.json").read_text())["people"][0]["pose_keypoints_2d"]
    neck = BODY25.index("neck")
    assert flat[3 * neck : 3 * neck + 3] == [20.0, 30.0, 0.6]
    assert flat[0:3] == [0.0, 0.0, 0.0]  # absent nose


def test_round_trip_coco18_keeps_the_joints_it_has(tmp_path, detections):
    folders = write_openpose(detections, tmp_path, skeleton="coco18")
    back = read_detections(folders, "openpose", sequence="demo", image_size=(1920, 1080))
    kept = sort_detections(detections[detections["joint"].isin(SKELETONS["coco18"].joints)])
    pd.testing.assert_frame_equal(back, kept)


def test_writer_refuses_existing_files_and_several_sequences(tmp_path, detections, detections_factory):
    write_openpose(detections, tmp_path)
    with pytest.raises(FormatError, match="overwrite=True"):
        write_openpose(detections, tmp_path)
    write_openpose(detections.iloc[:5], tmp_path, overwrite=True)
    assert len(list((tmp_path / "view_00").glob("*_keypoints.json"))) == 1
    two = pd.concat([detections, detections_factory(sequence="other")], ignore_index=True)
    with pytest.raises(FormatError, match="one sequence"):
        write_openpose(two, tmp_path / "x")
    with pytest.raises(FormatError, match="skeleton"):
        write_openpose(detections, tmp_path / "y", skeleton="coco17")


# --- bad input -----------------------------------------------------------------------------------------------------


def _one_file(tmp_path: Path, text: str) -> Path:
    folder = tmp_path / "v"
    folder.mkdir(exist_ok=True)
    (folder / "x_000000000000_keypoints.json").write_text(text)
    return folder


def _read(folder: Path):
    return read_detections([folder], "openpose", sequence="s", image_size=(640, 480), skeleton="body25")


def _message(excinfo) -> str:
    text = str(excinfo.value)
    assert "\n" not in text
    return text


@pytest.mark.parametrize(
    "text, field, expected",
    [
        ('{"people": [{"pose_keypoints_2d": [1, 2', None, "valid JSON"),
        ('{"version": 1.3}', "people", "'people' list"),
        ('{"people": [{"face_keypoints_2d": []}]}', "people[0].pose_keypoints_2d", "list of x, y, confidence"),
        (json.dumps({"people": [{"pose_keypoints_2d": [0.0] * 60}]}), "people[0].pose_keypoints_2d", "75 numbers"),
        (json.dumps({"people": [{"pose_keypoints_2d": [0.0] * 74 + ["a"]}]}), "people[0].pose_keypoints_2d",
         "numbers only"),  # fmt: skip
    ],
)
def test_bad_files_name_file_and_field(tmp_path, text, field, expected):
    folder = _one_file(tmp_path, text)
    with pytest.raises(FormatError) as excinfo:
        _read(folder)
    message = _message(excinfo)
    assert "x_000000000000_keypoints.json" in message and expected in message
    if field:
        assert f"field '{field}" in message


def test_nan_coordinates_of_a_scored_joint(tmp_path):
    flat = [0.0] * 75
    flat[3 * 4 : 3 * 4 + 3] = [float("nan"), 5.0, 0.8]
    folder = _one_file(tmp_path, json.dumps({"people": [{"pose_keypoints_2d": flat}]}))
    with pytest.raises(FormatError, match=r"joint 4 \(right_wrist\)'.*finite x, y") as excinfo:
        _read(folder)
    _message(excinfo)


def test_negative_confidence(tmp_path):
    flat = [0.0] * 75
    flat[2] = -0.5
    folder = _one_file(tmp_path, json.dumps({"people": [{"pose_keypoints_2d": flat}]}))
    with pytest.raises(FormatError, match="confidence'.*>= 0"):
        _read(folder)


def test_mixed_skeletons_in_one_sequence(tmp_path):
    _write_frame(tmp_path / "v", 0, [_person(25, {0: (1.0, 1.0, 1.0)})])
    _write_frame(tmp_path / "v", 1, [_person(18, {0: (1.0, 1.0, 1.0)})])
    with pytest.raises(FormatError, match="75 numbers .*got 54 numbers"):
        _read(tmp_path / "v")


def test_given_skeleton_must_match(tmp_path):
    _write_frame(tmp_path / "v", 0, [_person(25, {0: (1.0, 1.0, 1.0)})])
    with pytest.raises(FormatError, match="54 numbers"):
        read_detections([tmp_path / "v"], "openpose", sequence="s", image_size=(640, 480), skeleton="coco18")


def test_view_folders_with_different_frame_counts_are_matched_by_frame_number(tmp_path, caplog):
    for f in range(3):
        _write_frame(tmp_path / "a", f, [_person(25, {0: (1.0, 2.0, 0.9)})])
    for f in (1, 2):
        _write_frame(tmp_path / "b", f, [_person(25, {0: (3.0, 4.0, 0.8)})])
    with caplog.at_level("WARNING"):
        table = _read_two(tmp_path)
    assert sorted(map(tuple, table[["frame", "view"]].to_numpy().tolist())) == [(0, 0), (1, 0), (1, 1), (2, 0), (2, 1)]
    assert "different frames" in caplog.text and "{0: 3, 1: 2}" in caplog.text


def test_view_folders_with_different_counts_and_no_frame_numbers(tmp_path):
    for name in ("a", "b", "c"):
        (tmp_path / "a").mkdir(exist_ok=True)
        (tmp_path / "a" / f"{name}.json").write_text(json.dumps({"people": []}))
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "a.json").write_text(json.dumps({"people": []}))
    with pytest.raises(FormatError) as excinfo:
        _read_two(tmp_path)
    message = _message(excinfo)
    assert str(tmp_path / "a") in message and str(tmp_path / "b") in message
    assert "3 files" in message and "1 files" in message and "no frame numbers" in message


@pytest.mark.parametrize(
    "names, frames",
    [
        (["cam01.0000.json", "cam01.0001.json", "cam01.0002.json"], [0, 1, 2]),
        (["cam07_000000000010_keypoints.json", "cam07_000000000011_keypoints.json"], [10, 11]),
        (["cam07_000000000003_keypoints.json"], [3]),  # one file: the last number, not the camera's
        (["take2_cam3_f12.json", "take2_cam3_f4.json"], [4, 12]),
    ],
)
def test_frame_number_is_the_number_that_varies_not_the_camera_number(tmp_path, names, frames):
    folder = tmp_path / "v"
    folder.mkdir()
    for name in names:
        (folder / name).write_text(json.dumps({"people": []}))
    assert [f for f, _ in list_openpose_frames(folder)] == frames


def test_placeholder_people_without_keypoints_are_skipped_and_counted(tmp_path, caplog):
    placeholder = {"person_id": [-1], "pose_keypoints_2d": []}
    _write_frame(tmp_path / "v", 0, [placeholder, _person(25, {0: (1.0, 2.0, 0.9)}), placeholder])
    _write_frame(tmp_path / "v", 1, [placeholder])
    with caplog.at_level("INFO"):
        table = _read(tmp_path / "v")
    assert table[["frame", "det_id", "joint"]].values.tolist() == [[0, 0, "nose"]]
    assert table.attrs["skipped_placeholders"] == {0: 3}
    assert "skipped 3 placeholder" in caplog.text


def test_25_points_need_a_named_skeleton(tmp_path):
    _write_frame(tmp_path / "v", 0, [_person(25, {0: (1.0, 2.0, 0.9)})])
    with pytest.raises(FormatError) as excinfo:
        read_detections([tmp_path / "v"], "openpose", sequence="s", image_size=(640, 480))
    message = _message(excinfo)
    assert "clip_000000000000_keypoints.json" in message and "people[0].pose_keypoints_2d" in message
    assert "'body25' and 'body25b'" in message and "--skeleton" in message


def test_body25b_is_read_in_its_own_order(tmp_path):
    body25b = SKELETONS["body25b"]
    person = _person(25, {body25b.index("left_eye"): (5.0, 6.0, 0.9), body25b.index("top_head"): (5.0, 1.0, 0.9)})
    _write_frame(tmp_path / "v", 0, [person])
    as_b = read_detections([tmp_path / "v"], "openpose", sequence="s", image_size=(640, 480), skeleton="body25b")
    as_25 = _read(tmp_path / "v")
    assert as_b["joint"].tolist() == ["left_eye"]  # the head top is not canonical
    assert as_25["joint"].tolist() == ["left_ear"]  # BODY_25's index 18: the wrong joint, hence no guessing


def _read_two(root: Path):
    return read_detections([root / "a", root / "b"], "openpose", sequence="s", image_size=(640, 480),
                           skeleton="body25")


def test_missing_and_empty_folders(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such folder"):
        _read(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FormatError, match="_keypoints.json"):
        _read(tmp_path / "empty")


def test_image_size_is_required_for_openpose(tmp_path):
    _write_frame(tmp_path / "v", 0, [])
    with pytest.raises(FormatError, match="image_size=.*OpenPose JSON does not carry it"):
        read_detections([tmp_path / "v"], "openpose", sequence="s")


def test_scores_above_one_are_clipped_with_a_warning(tmp_path, caplog):
    _write_frame(tmp_path / "v", 0, [_person(25, {0: (1.0, 1.0, 1.04)})])
    with caplog.at_level("WARNING"):
        table = _read(tmp_path / "v")
    assert table["score"].tolist() == [1.0]
    assert "clipped" in caplog.text


def test_every_canonical_joint_survives_body25(tmp_path):
    assert set(CANONICAL_JOINTS) <= set(BODY25.joints)
