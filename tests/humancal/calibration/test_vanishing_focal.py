"""Vertical vanishing point and single-view focal length on exact and noisy vertical segments."""

import numpy as np
import pytest

from humancal.calibration.focal import solve_focal
from humancal.calibration.vanishing import fit_vertical_vanishing_point, line_angles_deg
from humancal.camera import Camera, project_points

W, H = 1920, 1080


def _camera(tilt_deg: float, focal_px: float = 1200.0, height_m: float = 3.0, roll_deg: float = 0.0) -> Camera:
    t, r = np.radians(tilt_deg), np.radians(roll_deg)
    forward = np.array([0.0, np.cos(t), -np.sin(t)])
    right = np.array([1.0, 0.0, 0.0])
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    roll = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1.0]])
    K = np.array([[focal_px, 0, W / 2], [0, focal_px, H / 2], [0, 0, 1.0]])
    return Camera.from_center(K, roll @ R, np.array([0.0, -6.0, height_m]), W, H)


def _segments(camera, n=150, seed=0, noise_px=1.0, heights=(1.2, 1.5)):
    """Vertical segments standing on z = 0.1 (ankle plane) spread over a 6 x 5 m floor in front of the camera."""
    rng = np.random.default_rng(seed)
    base = np.c_[rng.uniform(-3, 3, n), rng.uniform(-2.5, 2.5, n), np.full(n, 0.1)]
    h = rng.uniform(*heights, n)
    top, _ = project_points(camera, base + h[:, None] * [0, 0, 1.0])
    bottom, _ = project_points(camera, base)
    top += noise_px * rng.normal(size=top.shape)
    bottom += noise_px * rng.normal(size=bottom.shape)
    inside = (np.isfinite(top).all(1) & np.isfinite(bottom).all(1) & (top[:, 1] > 0) & (bottom[:, 1] < H)
              & (top[:, 0] > 0) & (top[:, 0] < W))
    return top[inside], bottom[inside], h[inside]


def _true_vp_h(camera):
    up = camera.R_cam_from_world @ [0, 0, 1.0]
    return np.array([camera.K[0, 0] * up[0], camera.K[1, 1] * up[1], up[2]])


@pytest.mark.parametrize("tilt", [25.0, 0.0])
def test_vanishing_point_matches_the_camera(tilt):
    cam = _camera(tilt, roll_deg=3.0)
    top, bottom, _ = _segments(cam)
    pp = cam.K[:2, 2]
    vp = fit_vertical_vanishing_point(top, bottom, pp, 0.5 * np.hypot(W, H), np.random.default_rng(0))
    truth = _true_vp_h(cam)
    est = vp.point_centered_h
    # compare as directions in the camera frame (K^-1 v), sign-free
    a = np.array([est[0] / 1200, est[1] / 1200, est[2]])
    b = np.array([truth[0] / 1200, truth[1] / 1200, truth[2]])
    cos = abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b)
    assert np.degrees(np.arccos(min(cos, 1.0))) < 0.3
    assert vp.inliers.mean() > 0.9
    if tilt == 0.0:
        assert abs(vp.point_h[2]) < 0.01  # at infinity


def test_vanishing_point_rejects_leaning_lines():
    cam = _camera(20.0)
    top, bottom, _ = _segments(cam, n=200, seed=1)
    rng = np.random.default_rng(2)
    bad = rng.random(len(top)) < 0.25
    top[bad] += rng.choice([-1, 1], (bad.sum(), 1)) * rng.uniform(60, 150, (bad.sum(), 1)) * [1, 0]
    vp = fit_vertical_vanishing_point(top, bottom, cam.K[:2, 2], 0.5 * np.hypot(W, H), rng)
    angles_true = line_angles_deg(_normalised(cam), (top - cam.K[:2, 2]) / (0.5 * np.hypot(W, H)),
                                  (bottom - cam.K[:2, 2]) / (0.5 * np.hypot(W, H)))
    assert np.mean(vp.inliers[bad]) < 0.1
    assert np.mean(vp.inliers[~bad]) > 0.9
    assert np.median(angles_true[vp.inliers]) < 0.5


def _normalised(cam):
    v = _true_vp_h(cam)
    s = 0.5 * np.hypot(W, H)
    p = np.array([v[0] / s, v[1] / s, v[2]])
    return p / np.linalg.norm(p)


def test_vanishing_point_needs_two_lines():
    with pytest.raises(ValueError, match="N >= 2"):
        fit_vertical_vanishing_point(np.zeros((1, 2)), np.ones((1, 2)), np.zeros(2), 100.0, np.random.default_rng(0))


def _solve(cam, **kw):
    top, bottom, h = _segments(cam, n=200, seed=3, noise_px=1.0)
    pp = cam.K[:2, 2]
    vp = fit_vertical_vanishing_point(top, bottom, pp, 0.5 * np.hypot(W, H), np.random.default_rng(0))
    return solve_focal(vp.point_centered_h, top - pp, bottom - pp, h, np.arange(len(h)) * 10,
                       focal_range_px=(300.0, 10000.0), **kw)


def test_focal_of_a_tilted_camera():
    cam = _camera(25.0, focal_px=1400.0, height_m=3.5)
    sol = _solve(cam)
    assert abs(sol.fx_px / 1400.0 - 1) < 0.02
    assert abs(sol.height_above_ankles_m - 3.4) < 0.1
    up_true = cam.R_cam_from_world @ [0, 0, 1.0]
    assert np.degrees(np.arccos(sol.up_cam @ up_true)) < 0.5
    assert sol.focal_rel_uncertainty < 0.05


def test_focal_fx_fy_when_asked():
    """fx and fy separate only when the vertical has an image-x component (roll); without roll fx is unseen."""
    sol = _solve(_camera(30.0, focal_px=1300.0, height_m=3.5, roll_deg=20.0), square_pixels=False)
    assert abs(sol.fx_px / 1300.0 - 1) < 0.05 and abs(sol.fy_px / 1300.0 - 1) < 0.05
    unseen = _solve(_camera(30.0, focal_px=1300.0, height_m=3.5, roll_deg=0.0), square_pixels=False)
    assert abs(unseen.fy_px / 1300.0 - 1) < 0.05
    assert unseen.focal_rel_uncertainty > 0.2


def test_level_camera_is_flagged_unobservable():
    """At tilt ~0 the heads' image heights do not depend on the focal: the uncertainty must say so."""
    sol = _solve(_camera(1.0, focal_px=1200.0, height_m=1.2))
    assert sol.focal_rel_uncertainty > 0.2
