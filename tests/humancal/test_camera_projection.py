"""Projection with OpenCV distortion: agreement with cv2.projectPoints, shapes, gradients."""

import cv2
import numpy as np
import pytest
import torch

from humancal.camera.projection import project_points_np, project_points_torch
from humancal.geometry.rotations import rotvec_to_rotmat

# realistic lens distortion (a wide-angle action camera, a mild webcam, a tangential-heavy lens)
DISTORTION = np.array([
    [-0.28, 0.09, 0.0012, -0.0008, -0.012],
    [0.05, -0.11, -0.0005, 0.0003, 0.04],
    [-0.12, 0.02, 0.004, 0.003, 0.0],
])


def _rig(rng, V=3):
    rotvec = rng.normal(scale=0.3, size=(V, 3))
    R = rotvec_to_rotmat(rotvec)
    t = rng.uniform([-0.5, -0.5, 4.0], [0.5, 0.5, 6.0], size=(V, 3))
    f = rng.uniform(800, 1500, size=V)
    K = np.zeros((V, 3, 3))
    K[:, 0, 0], K[:, 1, 1] = f, f * rng.uniform(0.98, 1.02, size=V)
    K[:, 0, 2], K[:, 1, 2], K[:, 2, 2] = 960 + rng.normal(size=V), 540 + rng.normal(size=V), 1.0
    return K, R, t, rotvec


def _points(rng, n=500):
    return rng.uniform([-2.0, -1.5, -1.0], [2.0, 1.5, 1.0], size=(n, 3))


def test_numpy_and_torch_agree_with_opencv_within_a_micropixel():
    rng = np.random.default_rng(0)
    K, R, t, rotvec = _rig(rng)
    X = _points(rng)
    px_np, depth = project_points_np(X, K, R, t, DISTORTION)
    px_t, _, in_front = project_points_torch(*(torch.from_numpy(a) for a in (X, K, R, t, DISTORTION)))
    assert px_np.shape == (3, 500, 2) and depth.shape == (3, 500) and bool(in_front.all())
    worst = 0.0
    for v in range(3):
        ref, _ = cv2.projectPoints(X, rotvec[v], t[v], K[v], DISTORTION[v])
        ref = ref.reshape(-1, 2)
        worst = max(worst, np.abs(px_np[v] - ref).max(), np.abs(px_t[v].numpy() - ref).max())
    assert worst < 1e-6
    # the distortion matters here: the ideal pinhole is pixels away
    px_ideal, _ = project_points_np(X, K, R, t)
    assert np.abs(px_ideal - px_np).max() > 5.0


def test_broadcast_shapes_per_view_points_and_single_camera():
    rng = np.random.default_rng(1)
    K, R, t, _ = _rig(rng)
    X = rng.uniform(-1, 1, size=(4, 3, 7, 3))  # (frames, views, points, 3)
    px, depth = project_points_np(X, K, R, t, DISTORTION)
    assert px.shape == (4, 3, 7, 2) and depth.shape == (4, 3, 7)
    one, _ = project_points_np(X[2, 1], K[1], R[1], t[1], DISTORTION[1])
    np.testing.assert_allclose(px[2, 1], one, atol=1e-12)
    with pytest.raises(ValueError, match=r"distortion must have shape \(3, 5\)"):
        project_points_np(X, K, R, t, DISTORTION[:, :4])
    with pytest.raises(ValueError, match=r"points_world_m must have shape \(\.\.\., N, 3\)"):
        project_points_np(X[..., :2], K, R, t)


def test_points_behind_the_camera_are_flagged():
    K = np.array([[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]])
    X = np.array([[0.1, 0.2, 3.0], [0.1, 0.2, -3.0], [0.0, 0.0, 0.0], [np.nan, 0.0, 1.0]])
    px, depth = project_points_np(X, K, np.eye(3), np.zeros(3), np.zeros(5))
    assert np.isfinite(px[0]).all() and np.isnan(px[1:]).all()
    np.testing.assert_allclose(depth[:2], [3.0, -3.0])
    Xt = torch.tensor(X[:3], requires_grad=True)
    pt, _, in_front = project_points_torch(Xt, *(torch.from_numpy(a) for a in (K, np.eye(3), np.zeros(3))))
    assert in_front.tolist() == [True, False, False]
    (pt[in_front] ** 2).sum().backward()
    assert torch.isfinite(Xt.grad).all() and (Xt.grad[1:] == 0).all()


def test_gradcheck_float64():
    rng = np.random.default_rng(2)
    K, R, t, _ = _rig(rng, V=2)
    args = [torch.from_numpy(a).requires_grad_() for a in (_points(rng, 6), K, R, t, DISTORTION[:2])]
    assert torch.autograd.gradcheck(lambda *a: project_points_torch(*a)[0], args, eps=1e-6, atol=1e-5)


def test_gradients_are_finite_at_the_image_border():
    K = torch.tensor([[900.0, 0, 960], [0, 900.0, 540], [0, 0, 1]], dtype=torch.float64)
    # rays through the corners of a 1920x1080 image and a little beyond, strongly distorted
    corners = torch.tensor([[-1.1, -0.62, 1.0], [1.1, 0.62, 1.0], [1.2, -0.7, 1.0]], dtype=torch.float64) * 3.0
    X = corners.clone().requires_grad_()
    d = torch.tensor([-0.28, 0.09, 0.0012, -0.0008, -0.012], dtype=torch.float64, requires_grad=True)
    px, _, in_front = project_points_torch(X, K, torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), d)
    assert bool(in_front.all())
    px.sum().backward()
    assert torch.isfinite(X.grad).all() and torch.isfinite(d.grad).all() and (X.grad.abs() > 0).any()


def test_many_points_in_one_call_float32():
    rng = np.random.default_rng(3)
    K, R, t, _ = _rig(rng, V=5)
    X = torch.from_numpy(rng.uniform(-1, 1, size=(64, 5, 23, 3))).float()
    px, depth, in_front = project_points_torch(X, *(torch.from_numpy(a).float() for a in (K, R, t)),
                                               torch.from_numpy(np.resize(DISTORTION, (5, 5))).float())
    assert px.shape == (64, 5, 23, 2) and px.dtype == torch.float32 and bool(in_front.all())
    ref, _ = project_points_np(X.double().numpy(), K, R, t, np.resize(DISTORTION, (5, 5)))
    assert np.abs(px.double().numpy() - ref).max() < 1e-2
