"""How well the calibration's bundle adjustment (:func:`~humancal.calibration.bundle.bundle_adjust`) determines its
cameras: the std of every camera parameter from the final normal equations, counted honestly (lifted poses'
correlated joints, the residuals' own noise, people repeated frame after frame).

Internal to the calibration package: :func:`~humancal.calibration.bundle.bundle_adjust` reports these stds.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from humancal.calibration.bundle_terms import _Problem, _arrow, _normal_equations, _residuals
from humancal.least_squares import solve_damped

__all__ = ["camera_std", "repeats"]

_REPEAT_DISTANCE_M = 0.1
"""Two groups whose keypoints are this close on average (metres) repeat one another (one still person seen in two
frames): their lifter and detector errors are the same, so they count as one in the focal uncertainty."""

logger = logging.getLogger("humancal.calibration.bundle")  # the bundle adjustment's messages


def camera_std(prob: _Problem, cams, R0, X, log_q, free, w_obs) -> np.ndarray:
    """(V, nc) std of every camera parameter that the data support (inverse Schur complement; inf where the final
    system is singular).

    Two corrections to the textbook covariance keep it honest: a lifted pose's errors are one wrong pose, strongly
    correlated over its 23 joints, so the shape term's information is counted as one joint's per lifted pose
    (its full weight made the focal lengths of near-planar rigs look determined to 1 % when they were 20 % off);
    and the pixel noise is the one the residuals show (the variance factor of the inlier reprojections), not the
    one assumed, when it is larger. Third, a person who does not move (seated, standing still) gives the same group
    frame after frame, with the same lifter and detector errors: each group's information is divided by the
    number of groups that repeat it (:func:`repeats`), so that a static scene counts its people once, not once
    per frame.
    """
    V, nc = prob.V, cams.shape[1]
    share = 1.0 / np.sqrt(repeats(X))  # (G,) whitened residuals scaled: information / repeats
    honest = replace(prob, shape_w=prob.shape_w / np.sqrt(prob.shape_w.shape[1]) * share[prob.s_group, None],
                     o_w=prob.o_w * share[prob.o_group])
    Hcc, Hcp, Hpp, gc, gp, _, _ = _normal_equations(honest, cams, R0, X, log_q, free)
    undamped = solve_damped(_arrow(Hcc, Hcp, Hpp, gc, gp), 0.0)
    S = undamped.reduced.numpy()
    if not (bool(undamped.blocks_factored.all()) and np.isfinite(S).all()):
        logger.warning("bundle adjustment: singular final system, focal uncertainties unknown")
        return np.full((V, nc), np.inf)
    try:
        cov = np.linalg.pinv(S)
    except np.linalg.LinAlgError:
        logger.warning("bundle adjustment: singular final system, focal uncertainties unknown")
        return np.full((V, nc), np.inf)
    r_obs = _residuals(prob, cams, R0, X, log_q)[0]
    inlier = w_obs >= 1.0
    variance_factor = float(np.mean(r_obs[inlier] ** 2)) if inlier.any() else 1.0
    diag = np.diagonal(cov).reshape(V, nc)
    return np.sqrt(np.maximum(diag, 0.0) * max(variance_factor, 1.0))


def repeats(X: np.ndarray, distance_m: float = _REPEAT_DISTANCE_M) -> np.ndarray:
    """(G,) how many groups (itself included) lie within ``distance_m`` of each group: the mean distance of their
    23 keypoints (NaN-free joints of both; (G, 23, 3) ``X``, metres)."""
    finite = np.isfinite(X).all(-1)
    Xf = np.where(finite[..., None], X, 0.0)
    counts = np.ones(len(X), np.int64)
    for g in range(len(X)):  # one row of the (G, G) distances at a time: memory linear in the groups
        both = finite[g] & finite  # (G, 23)
        distance = np.linalg.norm(Xf - Xf[g], axis=-1)
        mean = (distance * both).sum(-1) / np.maximum(both.sum(-1), 1)
        counts[g] = max(int(((mean < distance_m) & both.any(-1)).sum()), 1)
    return counts
