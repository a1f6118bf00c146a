"""Plausibility checks of calibrated cameras: focal lengths, rig geometry, proper rotations."""

import numpy as np
import pandas as pd
import pytest

from humancal.camera import Camera, cameras_to_table
from humancal.tables.plausibility import (
    CheckReport,
    check_body_size,
    check_cameras_valid,
    check_detections_plausible,
    check_focal_plausible,
    check_rig_geometry,
)


def _look_at(centre, target, f=1000.0, size=(1920, 1080)) -> Camera:
    """A camera at ``centre`` looking at ``target`` with image x horizontal (world Z up)."""
    z = np.asarray(target, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    K = np.array([[f, 0, size[0] / 2], [0, f, size[1] / 2], [0, 0, 1.0]])
    return Camera.from_center(K, np.stack([x, y, z]), np.asarray(centre, float), *size)


def _ring(n=4, radius=5.0, height=2.5):
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return [_look_at(np.array([radius * np.cos(a), radius * np.sin(a), height]), [0, 0, 1.0]) for a in angles]


PEOPLE = np.array([[0.5, 0.3, 0.0], [-0.4, 0.6, 0.0], [0.0, -0.7, 0.0]])


def test_a_ring_looking_at_its_people_passes_every_check():
    table = cameras_to_table(_ring(), "s")
    assert check_cameras_valid(table).passed
    assert check_focal_plausible(table).passed
    report = check_rig_geometry(table, PEOPLE)
    assert report.passed, report.description
    assert report.figures["min_people_in_view_fraction"] == 1.0


def test_a_camera_below_the_floor_or_looking_away_fails():
    cams = _ring()
    cams[1] = _look_at(np.array([0.0, 5.0, -0.5]), [0, 0, -1.0])
    cams[2] = _look_at(np.array([-5.0, 0.0, 2.5]), [-10.0, 0.0, 1.0])
    report = check_rig_geometry(cameras_to_table(cams, "s"), PEOPLE)
    assert not report.passed
    assert "view 1: camera centre -0.50 m is not above the floor" in report.description
    assert "view 2: only 0 % of the people" in report.description
    assert not check_rig_geometry(cameras_to_table(_ring(), "s"), np.zeros((0, 3))).passed


def test_without_a_floor_only_the_viewing_directions_are_checked():
    """Cameras in camera 0's frame (no floor found): heights mean nothing, people in front still do."""
    cams = _ring()
    cams[1] = _look_at(np.array([0.0, 5.0, -0.5]), [0, 0, 1.0])  # "below the floor" is no fault without a floor
    people = PEOPLE + [0.0, 0.0, 1.0]  # the people's own positions, used as given
    report = check_rig_geometry(cameras_to_table(cams, "s"), people, floor_known=False)
    assert report.passed and "no floor found" in report.description, report.description
    cams[2] = _look_at(np.array([-5.0, 0.0, 2.5]), [-10.0, 0.0, 1.0])
    report = check_rig_geometry(cameras_to_table(cams, "s"), people, floor_known=False)
    assert not report.passed and "view 2: only 0 % of the people" in report.description
    assert "above the floor" not in report.description


def test_a_mirrored_camera_is_not_right_handed():
    table = cameras_to_table(_ring(), "s")
    R = np.asarray(table.loc[0, "R_cam_from_world"]).reshape(3, 3).copy()
    R[0] *= -1.0
    table.at[0, "R_cam_from_world"] = R.ravel()
    report = check_cameras_valid(table)
    assert not report.passed and "view 0: rotation not proper" in report.description


def test_focal_plausibility():
    table = cameras_to_table(_ring(), "s")
    table.loc[1, ["fx_px", "fy_px"]] = 50.0  # a 174 deg field of view
    table.loc[2, "fy_px"] = 1500.0
    table.loc[3, ["fx_px", "fy_px"]] = np.nan  # not known yet: skipped and counted
    report = check_focal_plausible(table)
    assert not report.passed
    assert "view 1: focal 50 px gives a 174.0 deg horizontal field of view" in report.description
    assert "view 2: fx 1000 px and fy 1500 px differ by more than 20 %" in report.description
    assert report.figures["unknown_focal_views"] == 1.0
    ok = check_focal_plausible(pd.concat([table.iloc[[0]], table.iloc[[3]]]))
    assert ok.passed and "1 not known yet" in ok.description


def test_nothing_to_check_is_not_a_pass():
    empty = cameras_to_table(_ring(), "s").iloc[:0]
    for report in (check_cameras_valid(empty), check_focal_plausible(empty), check_rig_geometry(empty, PEOPLE)):
        assert not report.passed and report.not_checked
        assert report.description.startswith("not checked: ")
    unknown = cameras_to_table(_ring(), "s")
    unknown[["fx_px", "fy_px"]] = np.nan
    report = check_focal_plausible(unknown)
    assert not report.passed and report.not_checked
    assert report.description == "not checked: the focal length of all 4 views is not known"
    assert report.figures["unknown_focal_views"] == 4.0


def test_checks_that_examined_something_say_how_much():
    table = cameras_to_table(_ring(), "s")
    table.loc[3, ["fx_px", "fy_px"]] = np.nan
    assert check_focal_plausible(table).checked == 3
    assert check_cameras_valid(cameras_to_table(_ring(), "s")).checked == 4
    assert check_rig_geometry(cameras_to_table(_ring(), "s"), PEOPLE).checked == 4


def test_a_report_that_examined_nothing_cannot_pass():
    with pytest.raises(ValueError, match="examined nothing cannot pass"):
        CheckReport(True, "fine", checked=0)


def test_no_detections_at_all_fails():
    from humancal.tables.schemas import empty_table

    views = pd.DataFrame({"view": [0], "width_px": [640], "height_px": [480]})
    report = check_detections_plausible(empty_table("detections"), views)
    assert not report.passed and report.description == "no detections at all"


def test_people_of_the_wrong_size_fail_the_body_size_check():
    assert check_body_size(1.04).passed
    report = check_body_size(6.1)
    assert not report.passed and "6.10 times the size" in report.description
    assert not check_body_size(0.6).passed
    assert check_body_size(float("nan")).not_checked
