"""Grouping quality against projected ground truth, on scenes whose answer is known."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from evaluation.detection_quality import evaluate_grouping
from humancal.camera import Camera, project_points
from humancal.tables.schemas import TableError, validate_table

JOINTS = [
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
]  # fmt: skip

# A standing person, metres, world Z up, facing -Y: (x, z) offsets of the joints above.
_BODY_XZ = np.array(
    [(0.2, 1.45), (-0.2, 1.45), (0.25, 1.15), (-0.25, 1.15), (0.27, 0.9), (-0.27, 0.9),
     (0.1, 0.95), (-0.1, 0.95), (0.11, 0.5), (-0.11, 0.5), (0.12, 0.08), (-0.12, 0.08)]
)  # fmt: skip


def _camera(width_px: int = 1000, height_px: int = 800) -> Camera:
    # At (0, -6, 1) looking along +Y (world), x right, y down.
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    K = np.array([[800.0, 0.0, width_px / 2], [0.0, 800.0, height_px / 2], [0.0, 0.0, 1.0]])
    return Camera.from_center(K, R, np.array([0.0, -6.0, 1.0]), width_px, height_px)


def _person_world(x_m: float) -> np.ndarray:
    return np.column_stack([_BODY_XZ[:, 0] + x_m, np.zeros(len(JOINTS)), _BODY_XZ[:, 1]])


def _gt(people: dict[int, np.ndarray], frame: int = 0) -> pd.DataFrame:
    rows = [
        ("s", frame, pid, name, *xyz, True)
        for pid, X in people.items()
        for name, xyz in zip(JOINTS, X, strict=True)
    ]
    return pd.DataFrame(rows, columns=["sequence", "frame", "person_id", "joint", "x_m", "y_m", "z_m", "valid"])


def _dets(dets: list[np.ndarray], frame: int = 0, view: int = 0) -> pd.DataFrame:
    rows = [
        ("s", frame, view, d, name, x, y, 0.9)
        for d, xy in enumerate(dets)
        for name, (x, y) in zip(JOINTS, xy, strict=True)
        if np.isfinite(x)
    ]
    return pd.DataFrame(rows, columns=["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"])


def _metrics(ev) -> pd.Series:
    """Values by metric name, per-view rows as ``<metric>@<view>``."""
    m = ev.metrics
    names = [n if pd.isna(v) else f"{n}@{v}" for n, v in zip(m["metric"], m["view"])]
    return pd.Series(m["value"].to_numpy(), index=names)


def test_perfect_detections_of_two_people():
    cam = _camera()
    people = {0: _person_world(-1.0), 3: _person_world(1.0)}
    proj = {p: project_points(cam, X)[0] for p, X in people.items()}
    rng = np.random.default_rng(0)
    noise = [rng.normal(0, 2.0, (12, 2)) for _ in range(2)]
    ev = evaluate_grouping(_dets([proj[3] + noise[0], proj[0] + noise[1]]), _gt(people), [cam], dataset="toy")
    m = _metrics(ev)
    assert m["detection_recall"] == 1.0 and m["detection_recall@0"] == 1.0
    assert m["detection_fragment_rate"] == 0.0
    assert m["gt_person_views"] == 2 and m["matched_detections"] == 2
    expected = np.median(np.linalg.norm(np.concatenate(noise), axis=1))
    assert m["median_joint_error_px"] == pytest.approx(expected)
    pv = ev.person_views.set_index("person_id")
    assert pv.loc[3, "det_id"] == 0 and pv.loc[0, "det_id"] == 1
    validate_table(ev.metrics, "metrics")
    assert set(ev.metrics["method"]) == {"grouping"} and set(ev.metrics["dataset"]) == {"toy"}
    assert set(ev.metrics.loc[ev.metrics["metric"] == "median_joint_error_px", "unit"]) == {"px"}


def test_fragment_and_far_detection():
    cam = _camera()
    people = {0: _person_world(-1.0), 1: _person_world(1.0)}
    proj = {p: project_points(cam, X)[0] for p, X in people.items()}
    leg = np.full((12, 2), np.nan)
    leg[[8, 10]] = proj[0][[8, 10]] + 3.0  # left knee and ankle of person 0, detected apart
    far = proj[1] + (0.0, 200.0)  # person 1's shape, 200 px off: not close to anyone
    ev = evaluate_grouping(_dets([proj[0], leg, far]), _gt(people), [cam], dataset="toy")
    m = _metrics(ev)
    assert m["detection_recall"] == 0.5
    assert m["fragment_detections"] == 1 and m["detection_fragment_rate"] == 1.0
    det = ev.detections.set_index("det_id")
    assert det.loc[1, "fragment"] and det.loc[1, "nearest_person"] == 0
    assert not det.loc[2, "fragment"] and det.loc[2, "nearest_person"] == -1


def test_threshold_is_five_percent_of_the_diagonal():
    cam = _camera(1000, 750)  # diagonal 1250 px -> 62.5 px
    people = {0: _person_world(0.0)}
    proj = project_points(cam, people[0])[0]
    inside = evaluate_grouping(_dets([proj + (62.0, 0.0)]), _gt(people), [cam], dataset="toy")
    outside = evaluate_grouping(_dets([proj + (63.0, 0.0)]), _gt(people), [cam], dataset="toy")
    assert _metrics(inside)["detection_recall"] == 1.0
    assert _metrics(outside)["detection_recall"] == 0.0
    assert np.isnan(_metrics(outside)["median_joint_error_px"])


def test_only_visible_joints_are_compared_and_counted():
    cam = _camera()
    edge = _person_world(-3.95)  # at the image's left edge: only the three left arm joints project inside
    visible = (project_points(cam, edge)[0][:, 0] >= 0).sum()
    assert visible == 3
    people = {0: _person_world(0.0), 1: edge}
    dets = _dets([project_points(cam, people[0])[0]])
    ev = evaluate_grouping(dets, _gt(people), [cam], dataset="toy")
    pv = ev.person_views.set_index("person_id")
    assert pv.loc[1, "visible_joints"] == 3 and pv.loc[0, "visible_joints"] == 12
    assert not pv.loc[1, "counted"] and pv.loc[0, "counted"]  # 3 < half of 12
    assert _metrics(ev)["detection_recall"] == 1.0
    lenient = evaluate_grouping(dets, _gt(people), [cam], dataset="toy", min_visible_fraction=0.25)
    assert _metrics(lenient)["gt_person_views"] == 2 and _metrics(lenient)["detection_recall"] == 0.5
    # A detection of the edge person's visible arm only is compared on those joints.
    arm = np.full((12, 2), np.nan)
    arm[[0, 2, 4]] = project_points(cam, edge)[0][[0, 2, 4]] + 1.0
    dets = _dets([project_points(cam, people[0])[0], arm])
    both = evaluate_grouping(dets, _gt(people), [cam], dataset="toy", min_visible_fraction=0.25)
    assert _metrics(both)["detection_recall"] == 1.0


def test_per_view_rows_and_frames_without_ground_truth():
    cams = [_camera(), _camera(1200, 900)]
    people = {0: _person_world(0.0)}
    dets = pd.concat(
        [
            _dets([project_points(cams[0], people[0])[0]], view=0),
            _dets([project_points(cams[1], people[0])[0] + 80.0], view=1),  # off by 113 px > 75 px threshold
            _dets([project_points(cams[0], people[0])[0]], frame=1, view=0),  # no ground truth in frame 1
        ]
    )
    ev = evaluate_grouping(dets, _gt(people), cams, dataset="toy")
    m = _metrics(ev)
    assert m["detection_recall@0"] == 1.0 and m["detection_recall@1"] == 0.0
    assert m["detection_recall"] == 0.5 and m["gt_person_views"] == 2
    assert m["detections"] == 3 and m["detections@0"] == 2
    assert not ev.detections.query("frame == 1")["fragment"].any()


def test_errors():
    cam = _camera()
    gt = _gt({0: _person_world(0.0)})
    dets = _dets([project_points(cam, _person_world(0.0))[0]])
    with pytest.raises(ValueError, match="share no joint names"):
        evaluate_grouping(dets.assign(joint="nose"), gt, [cam], dataset="toy")
    with pytest.raises(ValueError, match=r"view\(s\) \[1\] but only 1 cameras"):
        evaluate_grouping(dets.assign(view=1), gt, [cam], dataset="toy")
    with pytest.raises(TableError, match="x_m"):
        evaluate_grouping(dets, gt.drop(columns="x_m"), [cam], dataset="toy")
    with pytest.raises(ValueError, match="threshold_fraction"):
        evaluate_grouping(dets, gt, [cam], dataset="toy", threshold_fraction=0.0)
