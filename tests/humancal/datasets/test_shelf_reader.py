"""Shelf reader: the 4D Association detection and ground-truth files, and the whole dataset when it is present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from evaluation.detection_quality import evaluate_grouping
from humancal.datasets.shelf import (
    SHELF15_JOINTS,
    load_shelf,
    read_candidate_file,
    read_shelf_gt,
    shelf_gt_table,
)
from humancal.formats import FormatError
from humancal.grouping import BODY25_LIMBS, GroupingConfig
from humancal.settings import DataRootError, dataset_dir
from humancal.tables.schemas import validate_table

WIDTH_PX, HEIGHT_PX = 1032, 776

# Two frames written out by hand. Frame 0: one nose, two necks, PAF neck->nose (limb 15) 2 x 1. Frame 1: one neck,
# one right shoulder, PAF neck->right shoulder (limb 7) 1 x 1. All other joints have no candidate, so every other
# PAF matrix is empty and contributes no number.
_ZERO_COUNTS_23 = "\n".join(["0"] * 23)
_ZERO_COUNTS_22 = "\n".join(["0"] * 22)
FIXTURE = f"""4 2
1
0.5
0.25
0.9
2
0.25 0.75
0.5 0.5
0.8 0.7
{_ZERO_COUNTS_23}
0.9
0.1
0
1
0.1
0.2
0.6
1
0.2
0.2
0.5
{_ZERO_COUNTS_22}
0.8
"""


def _write(tmp_path: Path, text: str, name: str = "0.txt") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_fixture_is_parsed_exactly(tmp_path):
    frames = read_candidate_file(_write(tmp_path, FIXTURE), WIDTH_PX, HEIGHT_PX)
    assert len(frames) == 2
    f0, f1 = frames
    assert f0.num_candidates == (1, 2) + (0,) * 23
    np.testing.assert_allclose(f0.xy_px[0], [[0.5 * WIDTH_PX, 0.25 * HEIGHT_PX]])
    np.testing.assert_allclose(f0.xy_px[1], [[258.0, 388.0], [774.0, 388.0]])
    np.testing.assert_allclose(f0.score[1], [0.8, 0.7])
    assert f0.limbs == BODY25_LIMBS
    np.testing.assert_allclose(f0.paf[15], [[0.9], [0.1]])  # limb (1, 0): rows = necks, columns = noses
    assert all(m.size == 0 for k, m in enumerate(f0.paf) if k != 15)
    assert f1.num_candidates == (0, 1, 1) + (0,) * 22
    np.testing.assert_allclose(f1.xy_px[2], [[0.2 * WIDTH_PX, 0.2 * HEIGHT_PX]])
    np.testing.assert_allclose(f1.paf[7], [[0.8]])


def _error(tmp_path: Path, text: str) -> str:
    path = _write(tmp_path, text, "bad.txt")
    with pytest.raises(FormatError) as info:
        read_candidate_file(path, WIDTH_PX, HEIGHT_PX)
    message = str(info.value)
    assert str(path) in message
    return message


def test_truncated_file_names_the_field(tmp_path):
    message = _error(tmp_path, FIXTURE.rstrip().rsplit("\n", 1)[0])
    assert "frame 1, limb 7 (neck, right_shoulder) PAF matrix (1 x 1)" in message
    assert "truncated" in message


def test_truncated_inside_a_joint(tmp_path):
    message = _error(tmp_path, "4 1\n1\n0.5\n0.25\n")
    assert "frame 0, joint 0 (nose) score row" in message


def test_nan_names_the_field_and_line(tmp_path):
    message = _error(tmp_path, FIXTURE.replace("0.8 0.7", "0.8 nan"))
    assert "frame 0, joint 1 (neck) score row (line 9)" in message
    assert "'nan'" in message


def test_negative_paf_score_is_rejected(tmp_path):
    message = _error(tmp_path, FIXTURE.replace("\n0.1\n0\n1\n", "\n-0.1\n0\n1\n"))
    assert "frame 0, limb 15 (neck, nose) PAF matrix (2 x 1)" in message
    assert ">= 0" in message


def test_non_integer_count(tmp_path):
    message = _error(tmp_path, FIXTURE.replace("4 2\n1\n", "4 2\n1.5\n"))
    assert "frame 0, joint 0 (nose) candidate count" in message
    assert "non-negative integer" in message


def test_count_too_large_or_too_small_is_caught(tmp_path):
    # One candidate announced too many for the necks: the numbers no longer line up and a count reads a coordinate.
    assert "count" in _error(tmp_path, FIXTURE.replace("\n2\n0.25 0.75", "\n3\n0.25 0.75"))
    # Numbers left after the announced frames.
    message = _error(tmp_path, FIXTURE + "0.5\n")
    assert "1 more value(s)" in message
    # A frame count larger than the frames present.
    assert "frame 2" in _error(tmp_path, FIXTURE.replace("4 2", "4 3", 1))


def test_wrong_skeleton_type(tmp_path):
    assert "header skeleton type" in _error(tmp_path, FIXTURE.replace("4 2", "3 2", 1))


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.txt"):
        read_candidate_file(tmp_path / "nothing.txt", WIDTH_PX, HEIGHT_PX)


def _gt_person(pid: int, offset: float) -> str:
    rows = [" ".join(f"{offset + 0.01 * j + c:.3f}" for j in range(15)) for c in range(3)]
    return f"{pid}\n" + "\n".join(rows) + "\n" + " ".join(["1"] * 15) + "\n"


GT_FIXTURE = "15 2\n2\n" + _gt_person(2, 0.0) + _gt_person(0, 5.0) + "0\n"


def test_gt_fixture(tmp_path):
    joints, present, valid = read_shelf_gt(_write(tmp_path, GT_FIXTURE, "gt.txt"))
    assert joints.shape == (2, 4, 15, 3)
    assert present.tolist() == [[True, False, True, False], [False] * 4]
    assert valid[0, 2].all() and not valid[1].any()
    np.testing.assert_allclose(joints[0, 2, 3], [0.03, 1.03, 2.03])
    np.testing.assert_allclose(joints[0, 0, 0], [5.0, 6.0, 7.0])
    assert np.isnan(joints[1]).all() and np.isnan(joints[0, 1]).all()
    table = shelf_gt_table(joints, present, valid)
    validate_table(table, "poses3d")
    assert len(table) == 2 * 15
    assert table["joint"].tolist()[:15] == list(SHELF15_JOINTS)
    row = table[(table.person_id == 2) & (table.joint == "left_hip")].iloc[0]
    np.testing.assert_allclose([row.x_m, row.y_m, row.z_m], [0.03, 1.03, 2.03])


@pytest.mark.parametrize(
    ("text", "field"),
    [
        (GT_FIXTURE.replace("2\n2\n", "2\n2\n7\n", 1).replace("\n7\n2\n", "\n7\n"), "frame 0, person 0 id"),
        ("15 1\n2\n" + _gt_person(1, 0.0) + _gt_person(1, 1.0), "frame 0, person 1 id"),
        (GT_FIXTURE.replace("0.010", "nan", 1), "frame 0, person id 2 X row"),
        (GT_FIXTURE.rsplit("\n", 3)[0], "frame 0, person id 0 validity row"),
        (GT_FIXTURE.replace("15 2", "14 2"), "header joint count"),
    ],
)
def test_gt_errors_name_the_field(tmp_path, text, field):
    path = _write(tmp_path, text, "gt.txt")
    with pytest.raises(FormatError) as info:
        read_shelf_gt(path)
    assert field in str(info.value)
    assert str(path) in str(info.value)


# --- the real dataset ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def shelf_root() -> Path:
    try:
        return dataset_dir("shelf_4dassoc")
    except DataRootError as err:
        pytest.skip(f"Shelf data not available: {err}")


@pytest.fixture(scope="module")
def shelf(shelf_root):
    return load_shelf(shelf_root)


def test_real_shelf_reader(shelf):
    assert shelf.num_frames == 301 and shelf.num_views == 5
    d = validate_table(shelf.detections, "detections")
    assert sorted(d["frame"].unique()) == list(range(301))
    assert sorted(d["view"].unique()) == list(range(5))
    assert d.groupby(["frame", "view"]).ngroups == 301 * 5
    assert shelf.image_size_px == ((1032, 776),) * 5
    assert shelf.detections.attrs["image_size_px"] == {v: (1032, 776) for v in range(5)}
    assert d["x_px"].between(0, 1032).all() and d["y_px"].between(0, 776).all()
    # Ground truth: frames with 0/1/2/3 people (SOURCE.md), pelvis = hip midpoint, ankles on the floor (Z up).
    assert np.bincount(shelf.gt_present.sum(1)).tolist() == [22, 92, 143, 44]
    J = shelf.gt_joints_world_m[shelf.gt_present]
    np.testing.assert_allclose(J[:, 14], 0.5 * (J[:, 2] + J[:, 3]), atol=1e-4)
    assert abs(np.median(J[:, [0, 5], 2])) < 0.1
    assert np.median(J[:, 13, 2]) > 1.5  # top of the head
    validate_table(shelf.gt_poses, "poses3d")
    assert len(shelf.gt_poses) == int(shelf.gt_present.sum()) * 15


def test_real_shelf_grouping_meets_targets(shelf):
    ev = evaluate_grouping(shelf.detections, shelf.gt_poses, shelf.cameras, dataset="shelf")
    m = ev.metrics[ev.metrics["view"].isna()].set_index("metric")["value"]
    assert m["gt_person_views"] == 2550  # every annotated person is inside every view
    assert m["detection_recall"] >= 0.95
    assert m["detection_fragment_rate"] <= 0.03
    assert m["median_joint_error_px"] <= 13.2  # the plain greedy tree's figure (DESIGN.md section 8)
    per_view = ev.metrics[ev.metrics["metric"] == "detection_recall"].dropna(subset=["view"])
    assert sorted(per_view["view"]) == list(range(5))
    assert (per_view["value"] >= 0.85).all()


def test_real_shelf_fragment_repair_is_what_meets_the_target(shelf_root):
    # Plain greedy tree without fragment repair: the fragment rate is above the target.
    plain = load_shelf(shelf_root, GroupingConfig(reattach=False, merge=None))
    ev = evaluate_grouping(plain.detections, plain.gt_poses, plain.cameras, dataset="shelf")
    m = ev.metrics[ev.metrics["view"].isna()].set_index("metric")["value"]
    assert m["detection_fragment_rate"] > 0.03
