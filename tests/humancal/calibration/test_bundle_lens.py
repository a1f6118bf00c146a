"""The bundle adjustment's lens terms: the analytic gradient against the cost's finite differences, and the
projection against OpenCV's."""

import cv2
import numpy as np

from humancal.calibration.bundle_terms import _normal_equations, _Problem, _project, _residuals, _robust_cost
from humancal.keypoints import NUM_JOINTS


def _problem(rng, square: bool, V=3, G=2):
    """A random problem with every joint of every group seen by every view, and the lens modelled."""
    groups, views, joints = np.meshgrid(np.arange(G), np.arange(V), np.arange(NUM_JOINTS), indexing="ij")
    o_group, o_view, o_joint = groups.ravel(), views.ravel(), joints.ravel()
    n_obs = len(o_group)
    s_group, s_view = np.repeat(np.arange(G), V), np.tile(np.arange(V), G)
    return _Problem(
        V=V, G=G, square=square, o_group=o_group, o_view=o_view, o_joint=o_joint,
        o_px=rng.normal(0.0, 200.0, (n_obs, 2)), o_w=rng.uniform(0.05, 0.2, n_obs),
        s_group=s_group, s_view=s_view, s_joints=rng.normal(0.0, 0.3, (G * V, NUM_JOINTS, 3)),
        shape_w=np.full((G * V, NUM_JOINTS), 5.0),
        log_f_mid=np.full(V, np.log(1200.0)), log_f_half=np.full(V, 1.0),
        prior_log_f=np.full(V, np.log(1100.0)), prior_w=np.full(V, 3.0), huber=1e9,
        scale_w=2.0, free_scale=True, lens=True, lens_prior_w=np.array([4.0, 10.0, 0.02, 0.02]),
    )


def _state(rng, p: _Problem):
    nf = 1 if p.square else 2
    cams = np.zeros((p.V, nf + 10))
    cams[:, :nf] = rng.normal(0.0, 0.3, (p.V, nf))
    # the rotation increments stay at zero: the solver folds them into R0 after every step, and the analytic
    # derivative is the one at zero
    cams[:, nf + 3 : nf + 6] = rng.normal(0.0, 0.2, (p.V, 3)) + [0.0, 0.0, 4.0]
    cams[:, nf + 6 :] = np.c_[rng.uniform(-0.3, 0.1, p.V), rng.uniform(-0.05, 0.1, p.V), rng.normal(0, 20, (p.V, 2))]
    R0 = np.stack([cv2.Rodrigues(rng.normal(0.0, 0.2, 3))[0] for _ in range(p.V)])
    X = rng.normal(0.0, 0.5, (p.G, NUM_JOINTS, 3))
    return cams, R0, X, rng.normal(0.0, 0.1, p.G)


def _cost(p, cams, R0, X, log_q):
    return _robust_cost(*_residuals(p, cams, R0, X, log_q)[:4], p.huber)


def test_gradient_is_the_cost_derivative_with_the_lens():
    rng = np.random.default_rng(0)
    for square in (True, False):
        p = _problem(rng, square)
        cams, R0, X, log_q = _state(rng, p)
        free = np.ones(cams.shape, bool)
        _, _, _, gc, gp, cost, _ = _normal_equations(p, cams, R0, X, log_q, free)
        assert np.isclose(cost, _cost(p, cams, R0, X, log_q))
        h = 1e-6
        numeric = np.zeros_like(cams)
        for index in np.ndindex(cams.shape):
            plus, minus = cams.copy(), cams.copy()
            plus[index] += h
            minus[index] -= h
            numeric[index] = (_cost(p, plus, R0, X, log_q) - _cost(p, minus, R0, X, log_q)) / (4 * h)
        np.testing.assert_allclose(gc, numeric, rtol=1e-4, atol=1e-4 * np.abs(numeric).max())
        numeric_x = np.zeros(X.size)
        for i in range(X.size):
            plus, minus = X.copy().ravel(), X.copy().ravel()
            plus[i] += h
            minus[i] -= h
            numeric_x[i] = (_cost(p, cams, R0, plus.reshape(X.shape), log_q)
                            - _cost(p, cams, R0, minus.reshape(X.shape), log_q)) / (4 * h)
        np.testing.assert_allclose(gp[:, :-1].ravel(), numeric_x, rtol=1e-4, atol=1e-4 * np.abs(numeric_x).max())


def test_projection_with_the_lens_is_opencvs():
    rng = np.random.default_rng(1)
    p = _problem(rng, square=False, V=1, G=1)
    P = np.c_[rng.uniform(-1.5, 1.5, (NUM_JOINTS, 2)), rng.uniform(2.0, 4.0, NUM_JOINTS)]
    fx, fy, k1, k2, dcx, dcy = 1000.0, 1010.0, -0.25, 0.08, 12.0, -7.0
    lens = np.array([[k1, k2, dcx, dcy]])
    ours = _project(p, np.array([fx]), np.array([fy]), lens, P)[0]
    K = np.array([[fx, 0.0, dcx], [0.0, fy, dcy], [0.0, 0.0, 1.0]])
    theirs = cv2.projectPoints(P, np.zeros(3), np.zeros(3), K, np.array([k1, k2, 0.0, 0.0, 0.0]))[0][:, 0]
    np.testing.assert_allclose(ours, theirs, atol=1e-9)
