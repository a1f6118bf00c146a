import numpy as np

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
