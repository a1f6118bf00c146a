import numpy as np
import pytest

from humancal.camera import Camera, project_points
from humancal.geometry.triangulation import reprojection_errors_px, triangulate_dlt


def _look_at(center, target):
    forward = (target - center) / np.linalg.norm(target - center)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward])  # rows: camera axes in world coordinates


def _ring(n=4, radius=4.0, height=2.0, f=1000.0):
    cams = []
    for a in np.linspace(0, 2 * np.pi, n, endpoint=False):
        c = np.array([radius * np.cos(a), radius * np.sin(a), height])
        K = np.array([[f, 0, 640], [0, f, 360], [0, 0, 1.0]])
        cams.append(Camera.from_center(K, _look_at(c, np.array([0, 0, 1.0])), c, 1280, 720))
    return cams


def test_exact_points_are_recovered():
    rng = np.random.default_rng(0)
    cams = _ring()
    X = rng.uniform([-1, -1, 0], [1, 1, 2], size=(50, 3))
    px = np.stack([project_points(c, X)[0] for c in cams])
    Xh, n = triangulate_dlt(cams, px, np.ones(px.shape[:2]))
    assert np.abs(Xh - X).max() < 1e-9
    assert (n == 4).all()
    assert np.nanmax(reprojection_errors_px(cams, Xh, px)) < 1e-6


def test_missing_views_and_min_views():
    cams = _ring()
    X = np.array([[0.2, 0.1, 1.0], [0.0, -0.3, 1.5]])
    px = np.stack([project_points(c, X)[0] for c in cams])
    w = np.ones((4, 2))
    w[1:, 1] = 0.0  # second point seen by one view only
    px[2, 0] = np.nan  # a NaN observation is treated as missing
    Xh, n = triangulate_dlt(cams, px, w)
    assert n.tolist() == [3, 0]
    assert np.abs(Xh[0] - X[0]).max() < 1e-9 and np.isnan(Xh[1]).all()


def test_outlier_pass_removes_a_flipped_view():
    cams = _ring(5)
    X = np.array([[0.3, 0.2, 1.2]])
    px = np.stack([project_points(c, X)[0] for c in cams])
    px[3, 0] += [150.0, -80.0]
    plain, _ = triangulate_dlt(cams, px, np.ones((5, 1)))
    robust, n = triangulate_dlt(cams, px, np.ones((5, 1)), outlier_threshold_px=20.0)
    assert np.linalg.norm(plain - X) > 0.01
    assert np.linalg.norm(robust - X) < 1e-9 and n[0] == 4


def test_shape_errors():
    cams = _ring(2)
    with pytest.raises(ValueError, match=r"points_px must have shape \(V=2, N, 2\)"):
        triangulate_dlt(cams, np.zeros((3, 4, 2)), np.ones((3, 4)))
    with pytest.raises(ValueError, match="non-negative"):
        triangulate_dlt(cams, np.zeros((2, 4, 2)), -np.ones((2, 4)))
