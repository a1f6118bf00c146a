"""COCO-style keypoint JSON (results lists and dataset files) and the read_detections dispatch."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from humancal.formats import DETECTION_FORMATS, FormatError, read_detections
from humancal.formats.skeletons import SKELETONS


def _keypoints(num_joints: int, present: dict[int, tuple[float, float, float]]) -> list[float]:
    flat = np.zeros((num_joints, 3))
    for j, xys in present.items():
        flat[j] = xys
    return flat.ravel().tolist()


def _write(path: Path, data) -> Path:
    path.write_text(json.dumps(data))
    return path


def test_results_list_with_integer_image_ids(tmp_path):
    path = _write(
        tmp_path / "view0.json",
        [
            {"image_id": 7, "category_id": 1, "keypoints": _keypoints(17, {0: (10.0, 11.0, 0.9)}), "score": 0.8},
            {"image_id": 7, "category_id": 1, "keypoints": _keypoints(17, {16: (12.0, 13.0, 0.5)}), "score": 0.7},
            {"image_id": 2, "category_id": 1, "keypoints": _keypoints(17, {5: (1.0, 2.0, 0.3)}), "score": 0.6},
            {"image_id": 2, "category_id": 3, "keypoints": _keypoints(17, {5: (9.0, 9.0, 0.9)}), "score": 0.9},
        ],
    )
    table = read_detections([path], "coco", sequence="s", image_size=(640, 480))
    got = [tuple(r) for r in table[["frame", "det_id", "joint", "x_px", "y_px", "score"]].itertuples(index=False)]
    assert got == [
        (2, 0, "left_shoulder", 1.0, 2.0, 0.3),  # the category-3 entry is skipped
        (7, 0, "nose", 10.0, 11.0, 0.9),
        (7, 1, "right_ankle", 12.0, 13.0, 0.5),
    ]


def test_halpe26_feet_reach_the_canonical_table(tmp_path):
    halpe = SKELETONS["halpe26"]
    kp = _keypoints(26, {halpe.index("left_heel"): (4.0, 5.0, 0.6), halpe.index("neck"): (1.0, 1.0, 0.9)})
    entry = {"image_id": "frame_000012.jpg", "category_id": 1, "keypoints": kp, "score": 1.0}
    path = _write(tmp_path / "v.json", [entry])
    table = read_detections({3: path}, "coco", sequence="s", image_size={3: (640, 480)})
    assert table[["frame", "view", "joint"]].values.tolist() == [[12, 3, "left_heel"]]


def test_string_image_ids_without_numbers_use_name_order(tmp_path):
    entries = [
        {"image_id": name, "keypoints": _keypoints(17, {0: (1.0, 1.0, 1.0)})} for name in ("b.jpg", "a.jpg", "c.jpg")
    ]
    path = _write(tmp_path / "v.json", entries)
    table = read_detections([path], "coco", sequence="s", image_size=(10, 10))
    assert table["frame"].tolist() == [0, 1, 2] and table["x_px"].tolist() == [1.0, 1.0, 1.0]
    by_order = read_detections([path], "coco", sequence="s", image_size=(10, 10), frame_from="name_order")
    assert by_order["frame"].tolist() == [0, 1, 2]
    with pytest.raises(FormatError, match="name_number"):
        read_detections([path], "coco", sequence="s", image_size=(10, 10), frame_from="name_number")


def test_dataset_file_gives_the_image_size(tmp_path):
    data = {
        "images": [
            {"id": 101, "file_name": "000000.jpg", "width": 1032, "height": 776},
            {"id": 102, "file_name": "000001.jpg", "width": 1032, "height": 776},
        ],
        "annotations": [{"image_id": 102, "category_id": 1, "keypoints": _keypoints(17, {9: (3.0, 4.0, 2.0)})}],
    }
    bad_id = dict(data, annotations=[dict(data["annotations"][0], image_id=5)])
    expected = r"field 'annotations\[0\].image_id': expected the id of an entry of 'images'"
    with pytest.raises(FormatError, match=expected):
        read_detections([_write(tmp_path / "bad.json", bad_id)], "coco", sequence="s")
    path = _write(tmp_path / "v.json", data)
    table = read_detections([path], "coco", sequence="s")
    assert table.attrs["image_size_px"] == {0: (1032, 776)}
    assert table[["frame", "joint", "score"]].values.tolist() == [[1, "left_wrist", 1.0]]  # visibility 2: labelled
    with pytest.raises(FormatError, match=r"image_size argument \(640, 480\).*\(1032, 776\) in the file"):
        read_detections([path], "coco", sequence="s", image_size=(640, 480))
    data["annotations"][0]["keypoints"][2] = 0.5
    with pytest.raises(FormatError, match="visibility'.*0, 1 or 2"):
        read_detections([_write(tmp_path / "u.json", data)], "coco", sequence="s")
    data["annotations"][0]["keypoints"][2] = 0
    data["images"][1]["width"] = 640
    with pytest.raises(FormatError, match="one image size per view"):
        read_detections([_write(tmp_path / "w.json", data)], "coco", sequence="s")


def test_results_list_needs_the_image_size_argument(tmp_path):
    path = _write(tmp_path / "v.json", [])
    with pytest.raises(FormatError, match="image_size=.*do not carry it"):
        read_detections([path], "coco", sequence="s")
    assert len(read_detections([path], "coco", sequence="s", image_size=(10, 10))) == 0  # empty file: valid, no rows


def test_unknown_format_lists_the_known_ones(tmp_path):
    with pytest.raises(FormatError, match=r"field 'format': expected one of \['openpose', 'coco'\], got 'alphapose'"):
        read_detections([tmp_path], "alphapose", sequence="s")
    assert DETECTION_FORMATS == ("openpose", "coco")


def test_image_size_forms(tmp_path):
    path = _write(tmp_path / "v.json", [])
    per_view = read_detections([path, path], "coco", sequence="s", image_size=[(1, 2), (3, 4)])
    assert per_view.attrs["image_size_px"] == {0: (1, 2), 1: (3, 4)}
    with pytest.raises(ValueError, match="one \\(width_px, height_px\\) per view"):
        read_detections([path, path], "coco", sequence="s", image_size=[(1, 2), (3, 4), (5, 6)])
    with pytest.raises(ValueError, match="positive integers"):
        read_detections([path], "coco", sequence="s", image_size=(0, 4))


# --- bad input -----------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "content, field, expected",
    [
        ('[{"image_id": 1, "keypoints": [1, 2', None, "valid JSON"),
        ('{"info": {}}', None, "COCO results list"),
        ('[{"keypoints": []}]', "[0].image_id", "the field is required"),
        ('[{"image_id": 1}]', "[0].keypoints", "the field is required"),
        (json.dumps([{"image_id": 1, "keypoints": [0.0] * 54}]), "[0].keypoints", "51 (coco17), 78 (halpe26)"),
        (json.dumps([{"image_id": 1, "keypoints": [0.0] * 50 + [None]}]), "[0].keypoints", "numbers only"),
        (json.dumps([{"image_id": 1, "keypoints": [0.0] * 50 + [-1.0]}]), "[0].keypoints joint 16 (right_ankle) score",
         ">= 0"),  # fmt: skip
        (json.dumps([{"image_id": -1, "keypoints": [0.0] * 51}]), "image_id", "non-negative integers"),
    ],
)
def test_bad_files_name_file_and_field(tmp_path, content, field, expected):
    path = tmp_path / "dets.json"
    path.write_text(content)
    with pytest.raises(FormatError) as excinfo:
        read_detections([path], "coco", sequence="s", image_size=(10, 10))
    message = str(excinfo.value)
    assert "\n" not in message and "dets.json" in message and expected in message
    if field:
        assert f"field '{field}'" in message


def test_nan_coordinates_of_a_scored_joint(tmp_path):
    kp = [0.0] * 51
    kp[3:6] = [1.0, float("nan"), 0.5]
    path = tmp_path / "dets.json"
    path.write_text(json.dumps([{"image_id": 0, "keypoints": kp}]))
    expected = r"dets.json: field '\[0\].keypoints joint 1 \(left_eye\)': expected finite x, y"
    with pytest.raises(FormatError, match=expected):
        read_detections([path], "coco", sequence="s", image_size=(10, 10))


def test_mixed_joint_counts_in_one_file(tmp_path):
    path = _write(
        tmp_path / "v.json",
        [{"image_id": 0, "keypoints": [0.0] * 51}, {"image_id": 1, "keypoints": [0.0] * 78}],
    )
    with pytest.raises(FormatError, match=r"\[1\].keypoints'.*51 numbers.*got 78"):
        read_detections([path], "coco", sequence="s", image_size=(10, 10))


def test_placeholder_entries_without_keypoints_are_skipped_and_counted(tmp_path):
    path = _write(
        tmp_path / "view0.json",
        [
            {"image_id": 0, "category_id": 1, "keypoints": [], "score": 0.0},
            {"image_id": 0, "category_id": 1, "keypoints": _keypoints(17, {0: (10.0, 11.0, 0.9)}), "score": 0.8},
            {"image_id": 1, "category_id": 1, "keypoints": [], "score": 0.0},
        ],
    )
    table = read_detections([path, path], "coco", sequence="s", image_size=(640, 480))
    assert table[["frame", "view", "det_id", "joint"]].values.tolist() == [[0, 0, 0, "nose"], [0, 1, 0, "nose"]]
    assert table.attrs["skipped_placeholders"] == {0: 2, 1: 2}
