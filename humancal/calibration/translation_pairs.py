"""The pair system of :func:`~humancal.calibration.translations.solve_focals_translations`: its assembly, the
reweighted passes that solve it (linear at ``s = 1``, then Gauss-Newton steps with a size correction per pair) and
the focal lengths' stds.

Internal to the calibration package: :func:`~humancal.calibration.translations.solve_focals_translations` is the
entry point (the model is in the docstrings of :mod:`.translations` and of that function).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, diags, hstack

from humancal.calibration.types import CalibrationError

__all__ = [
    "PairSystem",
    "pair_system",
    "ConditionedSystem",
    "conditioned_system",
    "Passes",
    "reweighted_passes",
    "focal_stds",
]


@dataclass(frozen=True)
class PairSystem:
    """The linear system of :func:`~.translations.solve_focals_translations` at ``s = 1``: unknowns
    ``x = (f (V), t (3V))``.

    Attributes:
        ok: (M_all,) the candidate pairs that enter (finite roots, a positive std); M: how many.
        A_pairs: (3M, 4V) sparse pair rows ``R_a^T z_a f_a - R_b^T z_b f_b - R_a^T t_a + R_b^T t_b``; rhs: (M, 3)
            their right-hand side (the roots' lateral parts), metres.
        A_extra, b_extra: camera 0 at the origin (stiff rows) and the focal priors in units of their std.
        col_scale: (4V, 4V) sparse column scaling (focal columns by a typical focal length).
        sigma: (M,) each pair's std, metres.
    """

    ok: np.ndarray
    M: int
    A_pairs: object
    rhs: np.ndarray
    A_extra: object
    b_extra: np.ndarray
    col_scale: object
    sigma: np.ndarray


def pair_system(roots, view, rows_a, rows_b, R_cam_from_world, focal_prior_px, focal_prior_rel_std, depth_rel_std,
                floor_std_m) -> PairSystem:
    """Assemble :class:`PairSystem` (arguments as :func:`~.translations.solve_focals_translations`)."""
    V = len(R_cam_from_world)
    # a pair enters only with finite roots and a positive std: one non-finite entry would make the whole normal
    # matrix non-finite, and LAPACK's least squares then fails ("SVD did not converge") instead of ignoring it
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.isfinite(roots.T_cam_m).all(1) & np.isfinite(roots.zeta_m_per_px)
        depth = 0.5 * (roots.T_cam_m[rows_a, 2] + roots.T_cam_m[rows_b, 2])
        ok = finite[rows_a] & finite[rows_b] & np.isfinite(floor_std_m + depth_rel_std * depth) & (
            floor_std_m + depth_rel_std * depth > 0)
    ra, rb = rows_a[ok], rows_b[ok]
    va, vb = view[ra], view[rb]
    M = len(ra)
    # unknowns: f (V), t (3V, t_0 fixed to 0 by a stiff prior row)
    n = 4 * V
    Rt = np.transpose(R_cam_from_world, (0, 2, 1))  # world_from_cam
    za = Rt[va][:, :, 2] * roots.zeta_m_per_px[ra, None]  # (M, 3) d(world point)/d f_a
    zb = Rt[vb][:, :, 2] * roots.zeta_m_per_px[rb, None]
    lat_a = np.einsum("mij,mj->mi", Rt[va], np.c_[roots.T_cam_m[ra, :2], np.zeros(M)])
    lat_b = np.einsum("mij,mj->mi", Rt[vb], np.c_[roots.T_cam_m[rb, :2], np.zeros(M)])
    rhs = lat_b - lat_a
    rows, cols, vals = [], [], []
    eq = np.arange(3 * M).reshape(M, 3)
    for k in range(3):
        rows += [eq[:, k], eq[:, k], eq[:, k], eq[:, k], eq[:, k], eq[:, k], eq[:, k], eq[:, k]]
        cols += [va, vb] + [V + 3 * va + i for i in range(3)] + [V + 3 * vb + i for i in range(3)]
        vals += [za[:, k], -zb[:, k]] + [-Rt[va][:, k, i] for i in range(3)] + [Rt[vb][:, k, i] for i in range(3)]
    A_pairs = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * M, n)).tocsr()
    # camera 0 at the origin (stiff rows), focal priors in units of their std
    prior_f = np.flatnonzero(np.isfinite(focal_prior_rel_std) & np.isfinite(focal_prior_px) & (focal_prior_px > 0))
    s = focal_prior_rel_std[prior_f] * focal_prior_px[prior_f]
    n_extra = 3 + len(prior_f)
    A_extra = coo_matrix(
        (np.r_[np.full(3, 1e3), 1.0 / s], (np.arange(n_extra), np.r_[V + np.arange(3), prior_f])), shape=(n_extra, n)
    ).tocsr()
    b_extra = np.r_[np.zeros(3), focal_prior_px[prior_f] / s]
    f_ref = float(np.nanmedian(focal_prior_px)) if np.isfinite(focal_prior_px).any() else 1000.0
    col_scale = diags(np.r_[np.full(V, f_ref), np.ones(3 * V)])
    sigma = floor_std_m + depth_rel_std * 0.5 * (roots.T_cam_m[ra, 2] + roots.T_cam_m[rb, 2])
    return PairSystem(ok, M, A_pairs, rhs, A_extra, b_extra, col_scale, sigma)


@dataclass(frozen=True)
class ConditionedSystem:
    """:class:`PairSystem` with its columns scaled (``y = col_scale^-1 x``), which keeps the normal matrix well
    conditioned.

    Attributes:
        Ps: (3M, 4V) sparse scaled pair rows; Pf, Pt: its focal (V) and translation (3V) columns.
        E_normal: (4V, 4V) normal matrix of the scaled gauge and prior rows; E_rhs: (4V,) their right-hand side.
        gauge: (3, 4V) sparse scaled rows fixing camera 0 at the origin.
    """

    Ps: object
    Pf: object
    Pt: object
    E_normal: np.ndarray
    E_rhs: np.ndarray
    gauge: object


def conditioned_system(system: PairSystem, V: int) -> ConditionedSystem:
    """The :class:`ConditionedSystem` of ``system`` (``V`` views)."""
    Ps = system.A_pairs @ system.col_scale  # scaled columns keep the normal matrix well conditioned
    Es = system.A_extra @ system.col_scale
    E_normal = (Es.T @ Es).toarray()
    E_rhs = Es.T @ system.b_extra
    gauge = Es[:3]
    return ConditionedSystem(Ps, Ps[:, :V], Ps[:, V:], E_normal, E_rhs, gauge)


@dataclass(frozen=True)
class Passes:
    """The solution after a stage of reweighted passes (:func:`reweighted_passes`).

    Attributes:
        y: (4V,) scaled unknowns; x: (4V,) the unknowns, focal lengths (pixels) then translations (metres).
        log_q: (M,) log of each pair's ``q = 1 / s`` (zeros at ``s = 1``): the residuals are in the lifted poses'
            units, so that ``(q, t) -> (q / c, c t)`` leaves them unchanged and only the prior fixes the overall
            scale (no shrinkage towards 0).
        res_m: (M, 3) each pair's residual (world distance of its two roots after the size correction), metres.
        r_norm: (M,) its norm in units of the pair's std (and of the robust residual scale, with the scales).
        reduced_data: (4V, 4V) the data's (reweighted) normal matrix in ``y``, the pair scales eliminated.
    """

    y: np.ndarray
    x: np.ndarray
    log_q: np.ndarray
    res_m: np.ndarray
    r_norm: np.ndarray
    reduced_data: np.ndarray


def reweighted_passes(system: PairSystem, conditioned: ConditionedSystem, weight: np.ndarray, y: np.ndarray | None,
                      log_q: np.ndarray, iterations: int, prior_s: float = 0.0,
                      inlier: np.ndarray | None = None) -> Passes:
    """``iterations + 1`` solves, Cauchy-reweighted in between, from the pair weights ``weight`` (M,).

    Without ``inlier``: linear solves at ``s = 1`` (``y`` unused). With ``inlier`` (M,): Gauss-Newton steps in
    ``(y, log q)`` from ``y`` and ``log_q`` (prior precision ``prior_s`` on each ``log q``) over the ``inlier``
    pairs, the residuals divided by a robust (median) scale.
    """
    V, M, sigma = conditioned.Pf.shape[1], system.M, system.sigma
    robust = 1.0  # residual scale relative to sigma, estimated with the scales
    for it in range(iterations + 1):
        w2 = np.repeat(weight**2, 3)
        if inlier is None:
            y, reduced_data = _linear_solve(system, conditioned, w2, V)
        else:
            y, log_q, reduced_data = _gauss_newton_step(system, conditioned, w2, y, log_q, prior_s, V)
        x = system.col_scale @ y
        q_rep = np.repeat(np.exp(log_q), 3)
        res_m = (system.A_pairs[:, :V] @ x[:V] - system.rhs.ravel()
                 + q_rep * (system.A_pairs[:, V:] @ x[V:])).reshape(M, 3)
        r_norm = np.linalg.norm(res_m, axis=1) / (np.sqrt(3.0) * sigma)  # in units of the pair's std
        if inlier is not None:
            # median of |r| / (sqrt(3) sigma) for 3D Gaussian residuals of std sigma: 0.888
            robust = float(np.clip(np.median(r_norm[inlier]) / 0.888, 0.1, 1.0))
            r_norm = r_norm / robust
        if it < iterations:
            weight = 1.0 / (robust * sigma * np.sqrt(1.0 + (r_norm / 2.0) ** 2))  # Cauchy
            if inlier is not None:
                weight = np.where(inlier, weight, 0.0)
    return Passes(y, x, log_q, res_m, r_norm, reduced_data)


def _linear_solve(system: PairSystem, conditioned: ConditionedSystem, w2: np.ndarray, V: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(4V,) scaled unknowns at ``s = 1`` for the (3M,) row weights ``w2`` (squared), and the (4V, 4V) data normal
    matrix."""
    Ps = conditioned.Ps
    data_normal = (Ps.T @ diags(w2) @ Ps).toarray()
    normal = data_normal + conditioned.E_normal
    y = _solve_normal(normal, Ps.T @ (w2 * system.rhs.ravel()) + conditioned.E_rhs, V)
    return y, data_normal


def _gauss_newton_step(system: PairSystem, conditioned: ConditionedSystem, w2: np.ndarray, y: np.ndarray,
                       log_q: np.ndarray, prior_s: float, V: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One Gauss-Newton step in ``(y, log q)``, the pair scales eliminated (each is a scalar block): the new (4V,)
    ``y``, (M,) ``log_q`` (its step clipped to +-0.3) and the (4V, 4V) reduced data normal matrix."""
    M, rhs, Pf, Pt, E_normal = system.M, system.rhs, conditioned.Pf, conditioned.Pt, conditioned.E_normal
    q_rep = np.repeat(np.exp(log_q), 3)
    baseline = Pt @ y[V:]  # (3M,) R_b^T t_b - R_a^T t_a of each pair
    r = Pf @ y[:V] - rhs.ravel() + q_rep * baseline
    Jx = hstack([Pf, diags(q_rep) @ Pt]).tocsr()
    jq = (q_rep * baseline).reshape(M, 3)  # d r / d log q_p
    Jq = coo_matrix((jq.ravel(), (np.arange(3 * M), np.repeat(np.arange(M), 3))),
                    shape=(3 * M, M)).tocsr()
    data_normal = (Jx.T @ diags(w2) @ Jx).toarray()
    H_xq = (Jx.T @ diags(w2) @ Jq).tocsr()  # (n, M), at most 8 entries per pair: kept sparse
    h_q = (w2.reshape(M, 3) * jq**2).sum(1) + prior_s
    g_x = Jx.T @ (w2 * r) + E_normal @ y - conditioned.E_rhs
    g_q = Jq.T @ (w2 * r) + prior_s * log_q
    reduced_data = data_normal - (H_xq @ diags(1.0 / h_q) @ H_xq.T).toarray()
    normal = reduced_data + E_normal
    dy = _solve_normal(normal, -(g_x - H_xq @ (g_q / h_q)), V)
    dq = -(g_q + H_xq.T @ dy) / h_q
    y = y + dy
    log_q = log_q + np.clip(dq, -0.3, 0.3)
    return y, log_q, reduced_data


def focal_stds(reduced_data: np.ndarray, E_normal: np.ndarray, gauge, col_scale, focal: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """(V,) relative stds of the focal lengths from the (reweighted, scales eliminated) normal equations, with the
    focal priors and without them (the data only, the gauge rows fixing camera 0)."""
    V = len(focal)
    cov = col_scale @ np.linalg.pinv(reduced_data + E_normal) @ col_scale
    f_std = np.sqrt(np.maximum(np.diag(cov)[:V], 0.0)) / np.maximum(np.abs(focal), 1e-9)
    cov_data = col_scale @ np.linalg.pinv(reduced_data + (gauge.T @ gauge).toarray(), rcond=1e-12) @ col_scale
    f_std_data = np.sqrt(np.maximum(np.diag(cov_data)[:V], 0.0)) / np.maximum(np.abs(focal), 1e-9)
    return f_std, f_std_data


def _solve_normal(normal: np.ndarray, rhs: np.ndarray, num_views: int) -> np.ndarray:
    """Minimum-norm solution of the (n, n) normal equations of :func:`~.translations.solve_focals_translations`.

    A singular system (a view without pairs leaves its translation free) is fine for ``lstsq``; a non-finite one
    is not (LAPACK's SVD does not converge): it raises :class:`CalibrationError` naming the views whose focal
    (column ``v``) or translation (columns ``V + 3 v ..``) carries the non-finite entries.
    """
    bad_columns = ~(np.isfinite(normal).all(0) & np.isfinite(rhs))
    if bad_columns.any():
        cols = np.flatnonzero(bad_columns)
        views = sorted({int(c) if c < num_views else int((c - num_views) // 3) for c in cols})
        raise CalibrationError(f"linear focal and translation solve: views {views} have non-finite equations "
                               "(their people's root positions are not finite)")
    return np.linalg.lstsq(normal, rhs, rcond=None)[0]
