"""Camera metrics: similarity alignment, focal / position / angle errors, reprojection against a floor."""

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from evaluation.camera_metrics import (
    camera_errors,
    camera_metrics,
    camera_metrics_table,
    centred_principal_point_floor,
    reprojection_errors_per_view,
)
from humancal.calibration.rig_alignment import Similarity
from humancal.camera import Camera, project_points
from humancal.keypoints import CANONICAL_JOINTS


def _look_at(center, target):
    forward = (target - center) / np.linalg.norm(target - center)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(forward, right), forward])


def _rig(n=4, f=1000.0):
    cams = []
    for k, a in enumerate(np.linspace(0, 2 * np.pi, n, endpoint=False)):
        c = np.array([5 * np.cos(a), 5 * np.sin(a), 2.0 + 0.3 * k])
        K = np.array([[f + 50 * k, 0, 640], [0, f + 50 * k, 360], [0, 0, 1.0]])
        cams.append(Camera.from_center(K, _look_at(c, np.array([0, 0, 1.0])), c, 1280, 720))
    return cams


def _moved(cams, sim: Similarity):
    return [sim.apply_to_camera(c) for c in cams]


def test_a_rig_moved_by_a_similarity_has_no_error():
    rig = _rig()
    sim = Similarity(0.3, Rotation.random(random_state=0).as_matrix(), np.array([4.0, -1.0, 2.0]))
    err = camera_errors(_moved(rig, sim), rig)
    assert np.allclose(err["focal_error_pct"], 0) and np.all(err["position_error_mm"] < 1e-6)
    assert np.all(err["angle_error_deg"] < 1e-5)
    assert np.isclose(err["alignment"].scale, 1 / 0.3)


def test_errors_measure_what_they_name():
    rig = _rig()
    est = list(rig)
    K = est[1].K.copy()
    K[0, 0] *= 1.1
    K[1, 1] *= 1.1
    est[1] = Camera(K, est[1].R_cam_from_world, est[1].t_cam_from_world_m, 1280, 720)
    err = camera_errors(est, rig)
    assert np.isclose(err["focal_error_pct"][1], 10.0) and np.allclose(err["focal_error_pct"][[0, 2, 3]], 0)
    # turning one camera about its centre changes only its angle error (the centres still align exactly)
    turn = Rotation.from_euler("y", 3.0, degrees=True).as_matrix()
    est[2] = Camera.from_center(rig[2].K, turn @ rig[2].R_cam_from_world, rig[2].center_world_m, 1280, 720)
    err = camera_errors(est, rig)
    assert np.isclose(err["angle_error_deg"][2], 3.0) and np.all(err["angle_error_deg"][[0, 1, 3]] < 1e-6)
    assert np.all(err["position_error_mm"] < 1e-6)
    # moving one centre by 10 cm: spread over the views by the least-squares alignment, largest on that view
    moved = Camera.from_center(rig[3].K, rig[3].R_cam_from_world, rig[3].center_world_m + [0.1, 0, 0], 1280, 720)
    err = camera_errors(est[:3] + [moved], rig)
    assert err["position_error_mm"].argmax() == 3 and 40 < err["position_error_mm"][3] < 100


def test_two_camera_rigs_align_with_their_optical_axes():
    rig = _rig(2)
    sim = Similarity(2.0, Rotation.random(random_state=3).as_matrix(), np.array([1.0, 2.0, 3.0]))
    err = camera_errors(_moved(rig, sim), rig)
    assert np.all(err["angle_error_deg"] < 1e-5) and np.all(err["position_error_mm"] < 1e-6)


def _people_tables(rig, noise_px=0.0, seed=0):
    rng = np.random.default_rng(seed)
    rows, assoc = [], []
    for frame in range(5):
        for person in range(2):
            X = rng.uniform([-1, -1, 0], [1, 1, 1.8], size=(len(CANONICAL_JOINTS), 3))
            for v, cam in enumerate(rig):
                px, _ = project_points(cam, X)
                px = px + noise_px * rng.normal(size=px.shape)
                for j, name in enumerate(CANONICAL_JOINTS):
                    rows.append(("s", frame, v, person, name, px[j, 0], px[j, 1], 0.9))
                assoc.append(("s", frame, v, person, person))
    det = pd.DataFrame(rows, columns=["sequence", "frame", "view", "det_id", "joint", "x_px", "y_px", "score"])
    ass = pd.DataFrame(assoc, columns=["sequence", "frame", "view", "det_id", "person_id"])
    return det, ass


def test_reprojection_is_zero_for_exact_detections_and_grows_with_camera_error():
    rig = _rig()
    det, ass = _people_tables(rig)
    assert np.all(reprojection_errors_per_view(rig, det, ass) < 1e-6)
    bad = list(rig)
    bad[0] = Camera.from_center(rig[0].K, rig[0].R_cam_from_world, rig[0].center_world_m + [0.3, 0, 0], 1280, 720)
    assert reprojection_errors_per_view(bad, det, ass).mean() > 1.0


def test_metric_rows_and_table():
    rig = _rig(3)
    det, ass = _people_tables(rig, noise_px=1.0)
    rows = camera_metrics(rig, rig, det, ass)
    names = {(r.metric, r.view) for r in rows}
    for base in ("focal_error_pct", "position_error_mm", "angle_error_deg", "reprojection_error_px",
                 "reprojection_error_gt_cameras_px"):
        assert (base, None) in names and {(base, v) for v in range(3)} <= names
    assert not any("/" in r.metric for r in rows)
    units = {r.metric: r.unit for r in rows}
    assert units["focal_error_pct"] == "%" and units["position_error_mm"] == "mm"
    assert units["angle_error_deg"] == "deg" and units["reprojection_error_px"] == "px"
    value = {r.metric: r.value for r in rows if r.view is None}
    assert value["reprojection_error_px"] == pytest.approx(value["reprojection_error_gt_cameras_px"])
    assert 0.3 < value["reprojection_error_px"] < 2.0
    table = camera_metrics_table("synthetic", "s", rig, rig)
    assert set(table["method"]) == {"init"} and len(table) == 3 * 4 + 1  # and the rig's scale_error_pct
    assert str(table["view"].dtype) == "Int32" and table["view"].isna().sum() == 4
    per_view = table[table["metric"] != "scale_error_pct"]
    assert per_view.groupby("metric")["view"].apply(lambda v: sorted(v.dropna())).tolist() == [[0, 1, 2]] * 3
    assert table.loc[table["metric"] == "scale_error_pct", "value"].abs().max() < 1e-9  # the true rig: no error
    with pytest.raises(ValueError, match="rigs differ"):
        camera_errors(rig[:2], rig)


def test_centred_principal_point_floor_is_the_offset_seen_as_a_rotation():
    rng = np.random.default_rng(3)
    points = rng.uniform([-1.5, -1.5, 0.0], [1.5, 1.5, 1.8], size=(400, 3))
    centred = _rig(3)
    offset = np.array([40.0, -25.0])
    moved = [Camera(c.K + np.array([[0, 0, offset[0]], [0, 0, offset[1]], [0, 0, 0]]), c.R_cam_from_world,
                    c.t_cam_from_world_m, c.width_px, c.height_px) for c in centred]

    floor = centred_principal_point_floor(moved, points)
    focal = np.array([c.K[0, 0] for c in moved])
    np.testing.assert_allclose(floor["offset_px"], np.hypot(*offset))
    # The re-estimated pose turns by about the angle the offset subtends, and moves little; the images barely show it.
    np.testing.assert_allclose(floor["angle_error_deg"], np.degrees(np.arctan(np.hypot(*offset) / focal)), rtol=0.15)
    assert (floor["position_error_mm"] < 100).all() and (floor["residual_px"] < 2.0).all()

    exact = centred_principal_point_floor(centred, points)
    np.testing.assert_allclose(exact["angle_error_deg"], 0.0, atol=1e-3)
    np.testing.assert_allclose(exact["position_error_mm"], 0.0, atol=1e-2)
    with pytest.raises(ValueError, match="at least 6 points"):
        centred_principal_point_floor(centred, points[:5])

