"""Focal length of one view from upright people: the vanishing point, their heights and the ground plane.

Model (pixels relative to the principal point, ``K = diag(fx, fy, 1)``): ``N`` is the world's up direction in
the camera frame (unit), the ankle midpoints of standing people lie on the plane ``N . X = -d`` (``d`` the
camera's height above the ankles, metres), and the head point is ``H_i = B_i + h_i N`` with ``h_i`` the
head-to-ankles height of person ``i`` from its lifted 3D pose. The vertical vanishing point is ``v = K N``.

Following the paper (III-B, after Fei et al. 2021), for a focal candidate ``f`` the up direction is
``N = K^-1 v``; the depths of head and ankles follow from ``lambda_H x_H - lambda_B x_B = h_i N`` (least
squares), which places every ankle centre in 3D; the right focal puts all of them on one plane orthogonal to
``N`` (equal ``d``). A log-spaced search over ``f`` of that plane spread initialises a joint refinement of
``(f [, fy], N, d)`` that minimises the head points' reprojection error (soft-L1).

Observability: at tilt 0 (optical axis horizontal) the vanishing point is at infinity and the head's image
height ``y_H = y_B (1 - h / d)`` does not depend on ``f`` at all, so a nearly level camera leaves the focal
length nearly unobservable. :func:`solve_focal` reports a relative uncertainty: the statistical standard
deviation from the Jacobian (inflated for the correlation of consecutive frames) combined with the change of
``f`` under a 3 % systematic error of all heights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

__all__ = ["FocalSolution", "solve_focal", "orient_up"]

_HEIGHT_BIAS = 0.03
"""Relative systematic height error assumed in the uncertainty (a lifter's typical scale bias)."""
_CELL_FRAMES, _CELL_PX = 30, 100.0
"""Candidates in one (frames // 30, 100 px cell of the ankles) count as one measurement in the uncertainty."""


@dataclass(frozen=True)
class FocalSolution:
    """Result of :func:`solve_focal`.

    Attributes:
        fx_px, fy_px: focal lengths, pixels.
        up_cam: (3,) world up direction in the camera frame (unit).
        height_above_ankles_m: camera height above the plane of the ankle centres, metres.
        focal_rel_uncertainty: relative uncertainty of the focal (see the module docstring).
        focal_rel_std: the statistical part of it alone.
        rms_px: RMS head reprojection residual over the inliers, pixels.
        inliers: (N,) candidates kept (residual under the outlier threshold).
    """

    fx_px: float
    fy_px: float
    up_cam: np.ndarray
    height_above_ankles_m: float
    focal_rel_uncertainty: float
    focal_rel_std: float
    rms_px: float
    inliers: np.ndarray


def orient_up(up: np.ndarray, fx: float, fy: float, head_c: np.ndarray, ankle_c: np.ndarray) -> np.ndarray:
    """Flip ``up`` (camera frame) so that moving an ankle point along it moves its image towards the head."""
    r = np.column_stack([ankle_c[:, 0] / fx, ankle_c[:, 1] / fy, np.ones(len(ankle_c))])
    dx = fx * (up[0] - r[:, 0] * up[2])
    dy = fy * (up[1] - r[:, 1] * up[2])
    e = head_c - ankle_c
    return up if np.sum(np.sign(dx * e[:, 0] + dy * e[:, 1])) >= 0 else -up


def _plane_heights(v_c: np.ndarray, fx: np.ndarray, fy: np.ndarray, head_c, ankle_c, h):
    """Ankle-plane distance ``d_i`` of every candidate for every focal candidate (the paper's constraint).

    Returns (G, N) distances (NaN where the depths come out negative).
    """
    G = len(fx)
    up = np.stack([v_c[0] / fx, v_c[1] / fy, np.full(G, v_c[2])], axis=1)
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    rh = np.stack([head_c[None, :, 0] / fx[:, None], head_c[None, :, 1] / fy[:, None], np.ones((G, len(h)))], -1)
    rb = np.stack([ankle_c[None, :, 0] / fx[:, None], ankle_c[None, :, 1] / fy[:, None], np.ones((G, len(h)))], -1)
    out = np.full((G, len(h)), np.nan)
    for g in range(G):
        n = orient_up(up[g], fx[g], fy[g], head_c, ankle_c)
        # Solve [rh, -rb] [lh, lb]^T = h n for every candidate (2x2 normal equations).
        a11 = (rh[g] * rh[g]).sum(1)
        a12 = -(rh[g] * rb[g]).sum(1)
        a22 = (rb[g] * rb[g]).sum(1)
        b1 = h * (rh[g] @ n)
        b2 = -h * (rb[g] @ n)
        det = a11 * a22 - a12**2
        lh = (a22 * b1 - a12 * b2) / det
        lb = (a11 * b2 - a12 * b1) / det
        d = -lb * (rb[g] @ n)
        out[g] = np.where((lh > 0) & (lb > 0) & (d > 0), d, np.nan)
    return out


def _residuals(params, square, up0, basis, head_c, ankle_c, h, sigmas):
    params = np.clip(params, -30.0, 30.0)  # log parameters: a trial step far out is a bad step, not an overflow
    fx = np.exp(params[0])
    fy = fx if square else np.exp(params[1])
    k = 1 if square else 2
    up = up0 + params[k : k + 2] @ basis
    up = up / np.linalg.norm(up)
    d = np.exp(params[k + 2])
    r = np.column_stack([ankle_c[:, 0] / fx, ankle_c[:, 1] / fy, np.ones(len(h))])
    s = np.minimum(r @ up, -1e-3)  # the ray must go down to the plane
    B = r * (d / -s)[:, None]
    H = B + h[:, None] * up
    z = np.maximum(H[:, 2], 1e-3)
    res = np.column_stack([fx * H[:, 0] / z - head_c[:, 0], fy * H[:, 1] / z - head_c[:, 1]])
    along_dir, sigma_along, sigma_across = sigmas
    along = (res * along_dir).sum(1)
    across = res[:, 0] * along_dir[:, 1] - res[:, 1] * along_dir[:, 0]
    return np.column_stack([along / sigma_along, across / sigma_across]).ravel()


def _fit(start, square, up0, basis, head_c, ankle_c, h, sigmas, log_f_bounds):
    k = 1 if square else 2
    lower = np.full(len(start), -np.inf)
    upper = np.full(len(start), np.inf)
    lower[:k], upper[:k] = log_f_bounds
    return least_squares(
        _residuals, np.clip(start, lower + 1e-9, upper - 1e-9), loss="soft_l1", f_scale=2.5,
        args=(square, up0, basis, head_c, ankle_c, h, sigmas), x_scale="jac", bounds=(lower, upper),
    )


def _sigmas(head_c, ankle_c, lean_std_deg, height_rel_std):
    """Unit line directions and the residual std along and across each line, pixels."""
    e = head_c - ankle_c
    length = np.linalg.norm(e, axis=1)
    jitter = np.sqrt(2.0) * np.maximum(0.01 * length, 1.0)  # both ends, ~1 % of the person's size
    along = np.hypot(jitter, height_rel_std * length)
    across = np.hypot(jitter, np.radians(lean_std_deg) * length)
    return e / length[:, None], along, across


def _take(sigmas, rows):
    return tuple(a[rows] for a in sigmas)


def _grid_start(vanishing_centered_h, head_c_px, ankle_c_px, h, focal_range_px):
    """Starting focal (pixels) and ankle-plane distance (metres): the one of 200 log-spaced focal candidates whose
    ankle centres spread least about one plane (3 m when none gives a plane)."""
    grid = np.geomspace(*focal_range_px, 200)
    d = _plane_heights(vanishing_centered_h, grid, grid, head_c_px, ankle_c_px, h)
    finite = np.isfinite(d).any(1)
    med = np.ones((len(grid), 1))
    if finite.any():
        med[finite] = np.nanmedian(d[finite], axis=1, keepdims=True)
    spread = np.where(np.isfinite(d), np.minimum(((d - med) / med) ** 2, 0.04), 0.04).mean(1)
    g = int(np.argmin(spread))
    f0 = grid[g]
    d0 = float(med[g, 0]) if finite[g] else 3.0
    return f0, d0


def _focal_uncertainty(fit, keep, frame, square_pixels, up0, basis, head_c_px, ankle_c_px, h, sig, bounds
                       ) -> tuple[float, float]:
    """Relative statistical std of the focal (inf at a bound of the search range) and its relative change under a
    systematic height error of ``_HEIGHT_BIAS`` (``fit`` over the candidates ``keep``)."""
    k = 1 if square_pixels else 2
    # Statistical std of log f from the Gauss-Newton covariance (residuals are in units of their std; a
    # worse fit than modelled scales it up), inflated by the number of candidates per distinct (30 frames,
    # 100 px cell of the ankles): a person standing still repeats nearly one measurement, and a person's lean
    # persists. Calibrated on 30 synthetic scenes: |error| / uncertainty has median 0.7 and 90 % quantile 1.8.
    m, p = fit.fun.size, fit.x.size
    scale2 = max(2.0 * fit.cost / max(m - p, 1), 1.0)
    cov = np.linalg.pinv(fit.jac.T @ fit.jac) * scale2
    key = np.column_stack([np.asarray(frame)[keep] // _CELL_FRAMES, np.round(ankle_c_px[keep] / _CELL_PX)])
    inflation = max(keep.sum() / len(np.unique(key, axis=0)), 1.0)
    rel_std = float(np.sqrt(max(cov[0, 0], 0.0) * inflation))
    # Sensitivity to a systematic height error: refit with all heights scaled.
    biased = _fit(fit.x, square_pixels, up0, basis, head_c_px[keep], ankle_c_px[keep], h[keep] * (1 + _HEIGHT_BIAS),
                  _take(sig, keep), bounds)
    rel_bias = float(abs(biased.x[0] - fit.x[0]))
    at_bound = np.any(np.abs(fit.x[:k] - np.array(bounds)[:, None]) < 0.01)
    if at_bound:  # the data pushed the focal to the end of the search range: not determined
        rel_std = float("inf")
    return rel_std, rel_bias


def solve_focal(
    vanishing_centered_h: np.ndarray,
    head_c_px: np.ndarray,
    ankle_c_px: np.ndarray,
    height_m: np.ndarray,
    frame: np.ndarray,
    *,
    focal_range_px: tuple[float, float],
    square_pixels: bool = True,
    lean_std_deg: float = 2.5,
    height_rel_std: float = 0.03,
    outlier_sigma: float = 4.0,
) -> FocalSolution:
    """Focal length(s), up direction and camera height of one view (see the module docstring).

    Residuals are the head point's reprojection error split along the observed line (std: 2D jitter and the
    relative height error ``height_rel_std``) and across it (std: 2D jitter and the lean of "upright" people
    from the true vertical, ``lean_std_deg``), so the Gauss-Newton covariance is in real units.

    Args:
        vanishing_centered_h: (3,) vertical vanishing point, homogeneous, pixels relative to the principal point.
        head_c_px, ankle_c_px: (N, 2) plumb-line tops and bottoms relative to the principal point, pixels.
        height_m: (N,) top height above the bottom point of each candidate, metres.
        frame: (N,) frame of each candidate (consecutive frames are correlated; used for the uncertainty).
        focal_range_px: (low, high) search range of the focal length, pixels.
        square_pixels: solve one focal (fx = fy) when True, fx and fy when False.
        lean_std_deg: std of the lean of upright people's plumb lines, degrees.
        height_rel_std: relative std of the heights from the lifted poses.
        outlier_sigma: candidates whose normalised residual exceeds this are dropped before the final fit.

    Returns:
        The :class:`FocalSolution`.
    """
    h = np.asarray(height_m, dtype=np.float64)
    sig = _sigmas(head_c_px, ankle_c_px, lean_std_deg, height_rel_std)
    f0, d0 = _grid_start(vanishing_centered_h, head_c_px, ankle_c_px, h, focal_range_px)
    up0 = vanishing_centered_h / np.array([f0, f0, 1.0])
    up0 = orient_up(up0 / np.linalg.norm(up0), f0, f0, head_c_px, ankle_c_px)
    basis = np.linalg.svd(up0[None])[2][1:]
    start = np.r_[np.log(f0), [] if square_pixels else [np.log(f0)], 0.0, 0.0, np.log(max(d0, 0.1))]
    bounds = (np.log(focal_range_px[0]), np.log(focal_range_px[1]))
    fit = _fit(start, square_pixels, up0, basis, head_c_px, ankle_c_px, h, sig, bounds)
    keep = np.linalg.norm(fit.fun.reshape(-1, 2), axis=1) < outlier_sigma
    if 3 <= keep.sum() < len(h):
        fit = _fit(fit.x, square_pixels, up0, basis, head_c_px[keep], ankle_c_px[keep], h[keep], _take(sig, keep),
                   bounds)
    else:
        keep = np.ones(len(h), bool)
    k = 1 if square_pixels else 2
    fx = float(np.exp(fit.x[0]))
    fy = fx if square_pixels else float(np.exp(fit.x[1]))
    up = up0 + fit.x[k : k + 2] @ basis
    up /= np.linalg.norm(up)
    rel_std, rel_bias = _focal_uncertainty(fit, keep, frame, square_pixels, up0, basis, head_c_px, ankle_c_px, h,
                                           sig, bounds)
    res = fit.fun.reshape(-1, 2) * np.column_stack([sig[1][keep], sig[2][keep]])
    return FocalSolution(
        fx_px=fx,
        fy_px=fy,
        up_cam=up,
        height_above_ankles_m=float(np.exp(fit.x[k + 2])),
        focal_rel_uncertainty=float(np.hypot(rel_std, rel_bias)),
        focal_rel_std=rel_std,
        rms_px=float(np.sqrt(np.mean(res**2))),
        inliers=keep,
    )
