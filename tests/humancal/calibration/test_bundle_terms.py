"""The bundle adjustment's Schur-complement step against the dense solve of the whole system."""

import numpy as np

from humancal.calibration.bundle_terms import _solve
from humancal.keypoints import NUM_JOINTS


def _random_system(rng, V=3, nc=7, G=4):
    """A symmetric positive definite Gauss-Newton system in the block layout of ``_normal_equations``."""
    J3 = 3 * NUM_JOINTS + 1  # the joints and the group's log scale
    n = V * nc + G * J3
    A = rng.normal(size=(2 * n, n))
    H = A.T @ A + 0.1 * np.eye(n)  # dense SPD; its off-block-diagonal point entries are dropped below
    cams = slice(0, V * nc)
    Hcc = np.stack([H[v * nc:(v + 1) * nc, v * nc:(v + 1) * nc] for v in range(V)])
    Hcp = np.stack([H[cams, V * nc + g * J3:V * nc + (g + 1) * J3].reshape(V, nc, J3) for g in range(G)])
    Hpp = np.stack([H[V * nc + g * J3:V * nc + (g + 1) * J3, V * nc + g * J3:V * nc + (g + 1) * J3]
                    for g in range(G)])
    gc, gp = rng.normal(size=(V, nc)), rng.normal(size=(G, J3))
    return Hcc, Hcp, Hpp, gc, gp


def _dense(Hcc, Hcp, Hpp, lam):
    V, nc = Hcc.shape[:2]
    G, J3 = Hpp.shape[:2]
    m = V * nc
    H = np.zeros((m + G * J3, m + G * J3))
    for v in range(V):
        H[v * nc:(v + 1) * nc, v * nc:(v + 1) * nc] = Hcc[v]
    for g in range(G):
        rows = slice(m + g * J3, m + (g + 1) * J3)
        H[:m, rows] = Hcp[g].reshape(m, J3)
        H[rows, :m] = Hcp[g].reshape(m, J3).T
        H[rows, rows] = Hpp[g] + lam * (np.diag(np.diag(Hpp[g])) + 1e-9 * np.eye(J3))
    H[:m, :m] += lam * np.diag(np.maximum(np.diag(H[:m, :m]), 1e-12))
    return H


def test_schur_step_is_the_dense_solution():
    rng = np.random.default_rng(3)
    Hcc, Hcp, Hpp, gc, gp = _random_system(rng)
    for lam in (0.0, 1e-3, 1.0):
        dc, dp, dq, _ = _solve(Hcc, Hcp, Hpp, gc, gp, lam)
        x = np.linalg.solve(_dense(Hcc, Hcp, Hpp, lam), -np.concatenate([gc.ravel(), gp.ravel()]))
        V, nc = gc.shape
        G = gp.shape[0]
        np.testing.assert_allclose(dc.ravel(), x[:V * nc], rtol=1e-6, atol=1e-9)
        points = x[V * nc:].reshape(G, -1)
        np.testing.assert_allclose(dp.reshape(G, -1), points[:, :-1], rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(dq, points[:, -1], rtol=1e-6, atol=1e-9)
