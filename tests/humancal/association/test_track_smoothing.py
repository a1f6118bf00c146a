"""The temporal refinement of tracked skeletons: the banded system is the stated objective, a wrong view in a
two-view frame is outvoted by the track, short gaps are interpolated and long ones are not, nothing is
extrapolated, rows without a person are left alone, and bad settings are refused."""

import numpy as np
import pytest

from humancal.association.cluster_triangulation import _linear_points, normal_equations
from humancal.association.track_smoothing import SmoothingConfig, smooth_tracks
from humancal.camera import Camera
from humancal.camera import look_at

FPS = 30.0


def ring(num_views: int = 3, radius_m: float = 5.0) -> list[Camera]:
    cameras = []
    K = np.array([[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]])
    for a in np.linspace(0, 2 * np.pi, num_views, endpoint=False):
        centre = np.array([radius_m * np.cos(a), radius_m * np.sin(a), 1.5])
        R = look_at(centre, np.array([0.0, 0.0, 1.0]))
        cameras.append(Camera(K, R, -R @ centre, 1280, 720))
    return cameras


def project(cameras: list[Camera], X: np.ndarray) -> np.ndarray:
    """(V, S, J, 2) pixels of (S, J, 3) points."""
    out = []
    for c in cameras:
        cam = X @ c.R_cam_from_world.T + c.t_cam_from_world_m
        uv = cam @ c.K.T
        out.append(uv[..., :2] / uv[..., 2:])
    return np.stack(out)


def walking(num_frames: int = 40, num_joints: int = 4, seed: int = 0) -> np.ndarray:
    """(T, J, 3) joints of one person walking on a curve, metres."""
    rng = np.random.default_rng(seed)
    t = np.arange(num_frames) / FPS
    path = np.stack([0.8 * t, 0.3 * np.sin(2 * t), np.full_like(t, 1.0)], -1)
    offsets = rng.uniform(-0.3, 0.3, (num_joints, 3))
    return path[:, None] + offsets[None]


def triangulated(cameras, points, weights):
    V, S, J = weights.shape
    X, _ = _linear_points(cameras, points.reshape(V, -1, 2), weights.reshape(V, -1))
    return X.reshape(S, J, 3)


def test_banded_solve_is_the_stated_objective():
    """One reweighting step from a start whose reprojection errors are 0 (Cauchy weights 1): the banded solution
    equals the dense solution of (A + smoothness) x = b (the ridge is negligible)."""
    cameras = ring()
    truth = walking(num_frames=12, num_joints=2)
    rng = np.random.default_rng(1)
    points = project(cameras, truth) + rng.normal(0, 2.0, (3, 12, 2, 2))
    weights = rng.uniform(0.5, 1.0, (3, 12, 2))
    start = truth.copy()  # errors vs the noisy points are small but not zero: reweight exactly as the code does
    config = SmoothingConfig(iterations=1)
    refined, filled = smooth_tracks(np.arange(12), np.zeros(12, np.int64), start, points, weights, cameras, FPS,
                                    config)
    assert not filled.any()
    # the same system, assembled densely
    from humancal.association.cluster_triangulation import reprojection_errors_px

    T, J = 12, 2
    x0 = start.transpose(1, 0, 2).reshape(-1, 3)  # ordered (joint, frame)
    pts = points.transpose(0, 2, 1, 3).reshape(3, -1, 2)
    w = weights.transpose(0, 2, 1).reshape(3, -1)
    errors, depth = reprojection_errors_px(cameras, x0, pts)
    robust = 1.0 / (1.0 + (errors / config.scale_px) ** 2)
    focal = np.array([c.K[0, 0] for c in cameras])
    A, b = normal_equations(cameras, pts, w * np.sqrt(robust) * focal[:, None] / depth / config.scale_px)
    n = T * J
    H = np.zeros((3 * n, 3 * n))
    for k in range(n):
        H[3 * k:3 * k + 3, 3 * k:3 * k + 3] = A[k]
    D = np.zeros((J * (T - 2), n))
    for j in range(J):
        for t in range(1, T - 1):
            D[j * (T - 2) + t - 1, j * T + t - 1:j * T + t + 2] = [1, -2, 1]
    inv_acc2 = (FPS * FPS / config.acceleration_mps2) ** 2
    H += np.kron(D.T @ D, np.eye(3)) * inv_acc2
    x = np.linalg.solve(H, b.reshape(-1)).reshape(J, T, 3).transpose(1, 0, 2)
    np.testing.assert_allclose(refined, x, atol=1e-5)


def test_a_wrong_view_in_a_two_view_frame_is_outvoted_by_the_track():
    cameras = ring(num_views=3)
    truth = walking()
    T, J = truth.shape[:2]
    rng = np.random.default_rng(2)
    points = project(cameras, truth) + rng.normal(0, 1.0, (3, T, J, 2))
    weights = np.ones((3, T, J))
    weights[2, 20] = 0.0  # frame 20: two views only
    points[1, 20, 0] += [60.0, -40.0]  # and one of them wrong for joint 0 (a flip, another person)
    frame_by_frame = triangulated(cameras, points, weights)
    refined, _ = smooth_tracks(np.arange(T), np.zeros(T, np.int64), frame_by_frame, points, weights, cameras, FPS)
    before = np.linalg.norm(frame_by_frame[20, 0] - truth[20, 0])
    after = np.linalg.norm(refined[20, 0] - truth[20, 0])
    assert before > 0.1
    assert after < 0.03, (before, after)
    # and the noise of every other frame goes down too
    err = lambda X: np.linalg.norm(X - truth, axis=-1)  # noqa: E731
    keep = np.arange(T) != 20
    assert err(refined)[keep].mean() < 0.8 * err(frame_by_frame)[keep].mean()


def test_short_gaps_are_filled_long_ones_and_the_ends_are_not():
    cameras = ring()
    truth = walking(num_frames=40, num_joints=3)
    T = len(truth)
    points = project(cameras, truth)
    weights = np.ones((3, T, 3))
    weights[:, 10:13, 0] = 0.0  # joint 0 unseen for 3 frames
    weights[:, 20:30, 1] = 0.0  # joint 1 unseen for 10 frames
    weights[:, 36:, 2] = 0.0  # joint 2 unseen at the end
    start = triangulated(cameras, points, weights)
    assert np.isnan(start[10:13, 0]).all()
    refined, filled = smooth_tracks(np.arange(T), np.zeros(T, np.int64), start, points, weights, cameras, FPS,
                                    SmoothingConfig(max_fill_frames=5))
    assert filled[10:13, 0].all() and filled.sum() == 3
    assert np.linalg.norm(refined[10:13, 0] - truth[10:13, 0], axis=-1).max() < 0.02
    assert np.isnan(refined[20:30, 1]).all()
    assert np.isnan(refined[36:, 2]).all()


def test_frames_apart_are_not_smoothed_together_and_other_rows_are_left_alone():
    """Two people, the second one 2 m away after a gap of 45 frames: with exact data the refinement stays within a
    millimetre everywhere (the smoothness would pull the two sides of the jump together if it linked them), and
    the -1 row is left as it was."""
    cameras = ring()
    a = walking(num_frames=10, num_joints=2, seed=3)
    b = walking(num_frames=10, num_joints=2, seed=4) + [0.0, 0.0, 0.2]
    b[5:] += [2.0, 0.0, 0.0]
    frames = np.r_[np.arange(10), np.arange(10) + np.r_[np.zeros(5, int), np.full(5, 50)], [3]]
    person = np.r_[np.zeros(10, int), np.ones(10, int), [-1]]
    X = np.concatenate([a, b, a[:1] + 5.0])
    points = project(cameras, X)
    weights = np.ones((3, 21, 2))
    refined, _ = smooth_tracks(frames, person, X, points, weights, cameras, FPS)
    np.testing.assert_allclose(refined[:20], X[:20], atol=1e-3)
    np.testing.assert_array_equal(refined[20], X[20])


@pytest.mark.parametrize("field,value", [("scale_px", 0.0), ("acceleration_mps2", -1.0), ("iterations", 0),
                                         ("max_fill_frames", -1), ("iterations", 1.5)])
def test_bad_settings_are_refused(field, value):
    with pytest.raises(ValueError, match=f"SmoothingConfig.{field}"):
        SmoothingConfig(**{field: value})


def test_mismatched_observations_are_refused():
    cameras = ring()
    X = walking(num_frames=5, num_joints=2)
    with pytest.raises(ValueError, match="points_px must be"):
        smooth_tracks(np.arange(5), np.zeros(5, int), X, np.zeros((2, 5, 2, 2)), np.ones((2, 5, 2)), cameras, FPS)
