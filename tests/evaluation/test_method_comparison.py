import numpy as np
import pandas as pd
import pytest

from evaluation.method_comparison import METHODS, _with_true_principal_points
from humancal.camera import Camera


def _camera(fx, cx, cy, k1=0.0):
    K = np.array([[fx, 0.0, cx], [0.0, fx * 1.01, cy], [0.0, 0.0, 1.0]])
    return Camera(K, np.eye(3), np.array([0.1, -0.2, 4.0]), 1032, 776, np.array([k1, 0, 0, 0, 0.0]))


def test_known_principal_point_diagnostic_takes_only_the_principal_point_from_the_truth():
    assert METHODS["int_ext_known_pp"].regime == "int_ext"  # focal and extrinsics still refined from the init
    estimated, truth = _camera(1000.0, 516.0, 388.0), _camera(1100.0, 551.0, 360.0, k1=-0.1)
    (moved,) = _with_true_principal_points([estimated], [truth])
    np.testing.assert_array_equal(moved.K[:2, 2], truth.K[:2, 2])
    np.testing.assert_array_equal(moved.K[[0, 1], [0, 1]], estimated.K[[0, 1], [0, 1]])
    np.testing.assert_array_equal(moved.distortion, estimated.distortion)
    np.testing.assert_array_equal(moved.t_cam_from_world_m, estimated.t_cam_from_world_m)
    assert estimated.K[0, 2] == 516.0  # the input is not changed in place


@pytest.mark.slow  # 30 s; the default run meets the row in tests/pipelines/test_association_assets.py
def test_convention_floor_row_scores_the_best_centred_cameras_without_a_fit():
    from evaluation.method_comparison import method_metric_table
    from humancal.datasets.sequences import SequenceSpec

    rng = np.random.default_rng(0)
    truth = []
    for k, angle in enumerate(np.linspace(0, 2 * np.pi, 4, endpoint=False)):
        centre = np.array([5 * np.cos(angle), 5 * np.sin(angle), 2.0])
        forward = -centre / np.linalg.norm(centre)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        R = np.stack([right, np.cross(forward, right), forward])
        K = np.array([[1000.0, 0, 516.0 + 30 * (k % 2)], [0, 1000.0, 388.0 - 20], [0, 0, 1]])  # off centre
        truth.append(Camera.from_center(K, R, centre, 1032, 776))
    points = rng.uniform([-1.0, -1.0, 0.0], [1.0, 1.0, 1.8], size=(200, 3))
    poses = pd.DataFrame({"sequence": "s", "frame": np.arange(200) // 20, "person_id": 0,
                          "joint": [f"j{i % 20}" for i in range(200)], "x_m": points[:, 0], "y_m": points[:, 1],
                          "z_m": points[:, 2], "valid": True})
    poses.loc[0, "valid"] = False
    table = method_metric_table(
        SequenceSpec("synthetic", "s", "synthetic"), methods=["convention_floor"], priors=lambda name: None, body=None,
        config=None, fps=30.0, dense=None, lifted=None, detections=None, associations=None, skeletons3d=None,
        cameras=truth, gt_associations=None, gt_poses3d=poses, gt_cameras=truth, gt_motions=None)
    mean = table[table["view"].isna()].set_index("metric")["value"]
    assert set(mean.index) == {"focal_error_pct", "position_error_mm", "angle_error_deg", "scale_error_pct"}
    assert set(table["method"]) == {"convention_floor"} and table["failed_checks"].isna().all()
    # About 30-36 px off centre at f = 1000 px: the cameras turn by about 2 degrees to make up for it.
    assert 1.0 < mean["angle_error_deg"] < 2.5 and mean["position_error_mm"] > 1.0

    # Too few true joints: the row is left out with a log line, the table is not broken.
    said = []
    empty = method_metric_table(
        SequenceSpec("synthetic", "s", "synthetic"), methods=["convention_floor"], priors=lambda name: None, body=None,
        config=None, fps=30.0, dense=None, lifted=None, detections=None, associations=None, skeletons3d=None,
        cameras=truth, gt_associations=None, gt_poses3d=poses.iloc[:4], gt_cameras=truth, gt_motions=None,
        log=said.append)
    assert empty.empty and "skipped" in said[0]
