"""The terms of the multi-view bundle adjustment (:mod:`.bundle`): the problem's data, the bounded focal
parameterization, the whitened residuals, the Huber weights and robust cost, and the normal equations, solved by the engine's
Schur-complement step (:mod:`humancal.least_squares`) with one block per group.

A view's parameter block is ``[focal (1: fx = fy, or 2: log fx, log fy, bounded), rotation increment (3),
translation (3)]``, followed, when the problem models the lens (``_Problem.lens``), by ``[k1, k2, dcx, dcy]``: OpenCV's
radial coefficients on the normalised image coordinates ``(x / z, y / z)`` and the principal point's offset from the
one given, pixels. A lens parameter moves only where ``free`` lets it; each has a zero-mean Gaussian prior
(``lens_prior_w``, 1 / std) that keeps a weakly observed one near the pinhole at the image centre.

Internal to the calibration package: :func:`humancal.calibration.bundle.bundle_adjust` is the entry point
and states the model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from scipy.linalg import block_diag

from humancal.geometry.rotations import rotvec_to_rotmat
from humancal.keypoints import JOINT_INDEX, NUM_JOINTS
from humancal.least_squares import ArrowSystem, solve_damped

_LHIP, _RHIP = JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]


def _skew(v: np.ndarray) -> np.ndarray:
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -v[..., 2], v[..., 1]
    K[..., 1, 0], K[..., 1, 2] = v[..., 2], -v[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -v[..., 1], v[..., 0]
    return K


@dataclass
class _Problem:
    V: int
    G: int
    square: bool
    # reprojection observations
    o_group: np.ndarray
    o_view: np.ndarray
    o_joint: np.ndarray
    o_px: np.ndarray  # (O, 2) relative to the principal point
    o_w: np.ndarray  # (O,) 1 / std
    # shape observations: one lifted pose per (group, detection)
    s_group: np.ndarray
    s_view: np.ndarray
    s_joints: np.ndarray  # (S, 23, 3)
    shape_w: np.ndarray  # (S, 23) 1 / std, 0 for joints without a finite lifted pose
    # focal bounds: log f = log_f_mid + log_f_half * tanh(u)
    log_f_mid: np.ndarray  # (V,)
    log_f_half: np.ndarray  # (V,)
    # focal priors
    prior_log_f: np.ndarray  # (V,)
    prior_w: np.ndarray  # (V,), 0 for none
    huber: float
    # per-group scale of the lifted poses (log q, q = lifted size / true size): prior weight, or fixed at 0
    scale_w: float = 0.0
    free_scale: bool = False
    # lens parameters (k1, k2, dcx, dcy) after the pose in every camera block, with their prior weights (1 / std)
    lens: bool = False
    lens_prior_w: np.ndarray = field(default_factory=lambda: np.zeros(4))


LENS_PARAMS = ("k1", "k2", "dcx_px", "dcy_px")
"""The lens parameters of a camera block, in order."""


def _focal_count(p: _Problem) -> int:
    return 1 if p.square else 2


def _camera_params(p: _Problem) -> int:
    return _focal_count(p) + 6 + (len(LENS_PARAMS) if p.lens else 0)


def _lens(p: _Problem, cams: np.ndarray) -> np.ndarray:
    """(V, 4) ``k1, k2, dcx_px, dcy_px`` of every view (zeros without a lens model)."""
    nf = _focal_count(p)
    return cams[:, nf + 6 : nf + 10] if p.lens else np.zeros((len(cams), len(LENS_PARAMS)))


def _log_focal(p: _Problem, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Log focal lengths from the bounded parameters ``u`` (V, nf), and ``d log f / d u``."""
    th = np.tanh(u)
    return p.log_f_mid[:, None] + p.log_f_half[:, None] * th, p.log_f_half[:, None] * (1.0 - th**2)


def _focal_parameters(p: _Problem, log_f: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_log_focal`, starting values kept inside 90 % of the range (the gradient vanishes at the
    bounds)."""
    return np.arctanh(np.clip((log_f - p.log_f_mid[:, None]) / p.log_f_half[:, None], -0.9, 0.9))


def _unpack(p: _Problem, cams: np.ndarray, R0: np.ndarray):
    nf = 1 if p.square else 2
    log_f, _ = _log_focal(p, cams[:, :nf])
    fx = np.exp(log_f[:, 0])
    fy = fx if p.square else np.exp(log_f[:, 1])
    R = rotvec_to_rotmat(cams[:, nf : nf + 3]) @ R0
    t = cams[:, nf + 3 : nf + 6]
    return fx, fy, R, t


def _project(p: _Problem, fx, fy, lens, P):
    """Pixels relative to the given principal points (O, 2) of camera-frame points ``P`` (O, 3), with the normalised
    coordinates ``n`` (O, 2), their squared radius ``r2`` (O,) and the radial factor ``1 + k1 r2 + k2 r2^2`` (O,)."""
    v = p.o_view
    z = np.where(P[:, 2] > 1e-6, P[:, 2], 1.0)
    n = P[:, :2] / z[:, None]
    r2 = (n**2).sum(1)
    radial = 1.0 + lens[v, 0] * r2 + lens[v, 1] * r2**2
    proj = np.stack([fx[v] * n[:, 0] * radial, fy[v] * n[:, 1] * radial], -1) + lens[v, 2:]
    return proj, n, r2, radial


def _residuals(p: _Problem, cams, R0, X, log_q):
    """Reprojection (O, 2), shape (S, 23, 3), focal prior (V,) (with the lens priors (V, 4) after it when the lens
    is modelled), scale prior (G,) residuals, all whitened."""
    fx, fy, R, t = _unpack(p, cams, R0)
    P = np.einsum("oij,oj->oi", R[p.o_view], X[p.o_group, p.o_joint]) + t[p.o_view]
    proj = _project(p, fx, fy, _lens(p, cams), P)[0]
    r_obs = (proj - p.o_px) * p.o_w[:, None]
    r_obs[P[:, 2] <= 1e-6] = 1e3  # behind the camera
    rel = X[p.s_group] - 0.5 * (X[p.s_group, _LHIP] + X[p.s_group, _RHIP])[:, None]
    q = np.exp(log_q)[p.s_group, None, None]
    r_shape = (q * (rel @ R[p.s_view].transpose(0, 2, 1)) - p.s_joints) * p.shape_w[..., None]
    nf = 1 if p.square else 2
    r_prior = (_log_focal(p, cams[:, :nf])[0].mean(1) - p.prior_log_f) * p.prior_w
    if p.lens:
        r_prior = np.concatenate([r_prior, (_lens(p, cams) * p.lens_prior_w).ravel()])
    r_scale = log_q * p.scale_w
    return r_obs, r_shape, r_prior, r_scale, (fx, fy, R, t, P)


def _huber_weights(norms: np.ndarray, k: float) -> np.ndarray:
    return np.where(norms <= k, 1.0, k / np.maximum(norms, 1e-12))


def _robust_cost(r_obs, r_shape, r_prior, r_scale, k):
    def rho(n):
        return np.where(n <= k, n**2, 2 * k * n - k**2)

    return float(rho(np.linalg.norm(r_obs, axis=1)).sum() + rho(np.linalg.norm(r_shape, axis=2)).sum()
                 + (r_prior**2).sum() + (r_scale**2).sum())


def _scatter_blocks(target: np.ndarray, index: np.ndarray, blocks: np.ndarray) -> None:
    """``target[index[s]] += blocks[s]`` with repeated indices summed (bincount over flat positions)."""
    size = int(np.prod(target.shape[1:]))
    flat = index[:, None] * size + np.arange(size)
    target += np.bincount(flat.ravel(), blocks.reshape(len(index), -1).ravel(), minlength=target.size).reshape(
        target.shape)


def _normal_equations(p: _Problem, cams, R0, X, log_q, free_cam):
    """Gauss-Newton blocks: Hcc (V, nc, nc), Hcp (G, V, nc, 3J + 1), Hpp (G, 3J + 1, 3J + 1), gc (V, nc),
    gp (G, 3J + 1); the last point parameter of a group is its log scale ``log q``. Also the robust cost and the
    reprojections' Huber weights (O,).

    The terms are added in order: the reprojections (:func:`_reprojection_terms`), the lifted poses' shapes
    (:func:`_add_shape_terms`), the groups' scales (:func:`_scale_terms`), the priors (:func:`_add_priors`); then the
    fixed camera parameters are taken out (:func:`_hold_fixed`)."""
    residuals = _residuals(p, cams, R0, X, log_q)
    r_obs, r_shape, r_prior, r_scale, _ = residuals
    w_obs = _huber_weights(np.linalg.norm(r_obs, axis=1), p.huber)
    w_shape = _huber_weights(np.linalg.norm(r_shape, axis=2), p.huber)  # (S, 23)
    Hcc, gc, Hcp, Hpp, gp, dlogf = _reprojection_terms(p, cams, residuals, w_obs)
    J3 = 3 * NUM_JOINTS
    Hpp_joints = Hpp[:, :J3, :J3].reshape(p.G, NUM_JOINTS, 3, NUM_JOINTS, 3)  # a view
    rel, Rrel, w2, ws, qs, rs = _add_shape_terms(p, X, log_q, residuals, w_shape, Hcc, gc, Hcp, Hpp_joints, gp)
    gp, Hcp = _scale_terms(p, residuals[3], rel, Rrel, w2, ws, qs, rs, Hpp, gp, Hcp)
    _add_priors(p, dlogf, r_prior, Hcc, gc)
    Hcc = _hold_fixed(Hcc, gc, Hcp, free_cam)
    return Hcc, Hcp, Hpp, gc, gp, _robust_cost(r_obs, r_shape, r_prior, r_scale, p.huber), w_obs


def _reprojection_terms(p: _Problem, cams, residuals, w_obs):
    """The reprojections' blocks: d r / d P (2x3) chained to the camera and point parameters. Returns Hcc, gc,
    Hcp (without the scale column), Hpp (with it, zero), gp (without it) and d log f / d u (V, nf)."""
    nc = _camera_params(p)
    nf = 1 if p.square else 2
    J3 = 3 * NUM_JOINTS
    r_obs, _, _, _, (fx, fy, R, t, P) = residuals
    v, O = p.o_view, len(p.o_view)
    behind = P[:, 2] <= 1e-6  # their residual is a constant penalty: no gradient
    z = np.where(behind, 1.0, P[:, 2])
    lens = _lens(p, cams)
    _, n, r2, radial = _project(p, fx, fy, lens, P)
    # d pixel / d normalised coordinates: diag(f) (radial I + 2 radial' n n^T), radial' = k1 + 2 k2 r2
    slope = lens[v, 0] + 2.0 * lens[v, 1] * r2
    f2 = np.stack([fx[v], fy[v]], -1)  # (O, 2)
    dn = f2[:, :, None] * (radial[:, None, None] * np.eye(2) + 2.0 * slope[:, None, None] * n[:, :, None] * n[:, None, :])
    dnP = np.zeros((O, 2, 3))  # d n / d P
    dnP[:, 0, 0] = dnP[:, 1, 1] = 1.0 / z
    dnP[:, :, 2] = -n / z[:, None]
    scale = (np.where(behind, 0.0, p.o_w) * np.sqrt(w_obs))[:, None, None]
    dP = (dn @ dnP) * scale
    Jc = np.zeros((O, 2, nc))
    distorted = f2 * n * radial[:, None] * scale[:, :, 0]  # d pixel / d log f
    if p.square:
        Jc[:, :, 0] = distorted
    else:
        Jc[:, 0, 0], Jc[:, 1, 1] = distorted[:, 0], distorted[:, 1]
    if p.lens:
        Jc[:, :, nf + 6] = f2 * n * r2[:, None] * scale[:, :, 0]  # k1
        Jc[:, :, nf + 7] = f2 * n * (r2**2)[:, None] * scale[:, :, 0]  # k2
        Jc[:, 0, nf + 8] = Jc[:, 1, nf + 9] = scale[:, 0, 0]  # principal point offsets
    _, dlogf = _log_focal(p, cams[:, :nf])  # (V, nf)
    Jc[:, :, :nf] *= dlogf[v][:, None, :]
    RX = P - t[v]
    Jc[:, :, nf : nf + 3] = -dP @ _skew(RX)
    Jc[:, :, nf + 3 : nf + 6] = dP
    Jp = dP @ R[v]  # (O, 2, 3)
    r = r_obs * np.sqrt(w_obs)[:, None]

    Hcc = np.zeros((p.V, nc, nc))
    for view in range(p.V):  # one product per view: its rows of the Jacobian stacked
        rows = Jc[v == view].reshape(-1, nc)
        Hcc[view] = rows.T @ rows
    gc = np.zeros((p.V, nc))
    _scatter_blocks(gc, v, np.einsum("ori,or->oi", Jc, r))
    Hcp = np.zeros((p.G, p.V, nc, J3))
    cols = 3 * p.o_joint[:, None] + np.arange(3)
    blk = Jc.transpose(0, 2, 1) @ Jp  # (O, nc, 3)
    flat = ((p.o_group * p.V + v)[:, None, None] * nc + np.arange(nc)[None, :, None]) * J3 + cols[:, None, :]
    Hcp += np.bincount(flat.ravel(), blk.ravel(), minlength=Hcp.size).reshape(Hcp.shape)
    # the point blocks, with the group's log scale as the last row and column (filled below); a reprojection
    # only touches the 3 x 3 block of its own joint
    Hpp = np.zeros((p.G, J3 + 1, J3 + 1))
    Hpp_joints = Hpp[:, :J3, :J3].reshape(p.G, NUM_JOINTS, 3, NUM_JOINTS, 3)  # a view
    joint_blocks = np.zeros((p.G * NUM_JOINTS, 3, 3))
    _scatter_blocks(joint_blocks, p.o_group * NUM_JOINTS + p.o_joint, Jp.transpose(0, 2, 1) @ Jp)
    every_joint = np.arange(NUM_JOINTS)
    Hpp_joints[:, every_joint, :, every_joint, :] += joint_blocks.reshape(p.G, NUM_JOINTS, 3, 3).transpose(1, 0, 2, 3)
    gp = np.bincount((p.o_group[:, None] * J3 + cols).ravel(), np.einsum("ori,or->oi", Jp, r).ravel(),
                     minlength=p.G * J3).reshape(p.G, J3)

    return Hcc, gc, Hcp, Hpp, gp, dlogf


def _add_shape_terms(p: _Problem, X, log_q, residuals, w_shape, Hcc, gc, Hcp, Hpp_joints, gp):
    """Add the lifted poses' shape terms to the blocks (in place); returns what the scale terms reuse: the joints
    relative to the hips (S, 23, 3) and turned into the camera (S, 23, 3), the squared weights with q^2 (S, 23),
    the weights (S, 23), the scales q (S,) and the weighted residuals (S, 23, 3)."""
    nf = 1 if p.square else 2
    J3 = 3 * NUM_JOINTS
    _, r_shape, _, _, (_, _, R, _, _) = residuals
    # --- shape: r_k = w_k (R_v (X_k - (X_lh + X_rh)/2) - L_k); d r_k / d X_m = w_k R_v D[k, m] with
    # D = I - 1 c^T (c = 1/2 at both hips). R_v^T R_v = I makes the point block (D^T W^2 D) kron I_3.
    # with the group's scale q: r_k = w_k (q R_v rel_k - L_k); every derivative gains a factor q
    sv, S = p.s_view, len(p.s_view)
    qs = np.exp(log_q)[p.s_group]  # (S,)
    ws = p.shape_w * np.sqrt(w_shape)  # (S, 23)
    Rs = R[sv]
    rel = X[p.s_group] - 0.5 * (X[p.s_group, _LHIP] + X[p.s_group, _RHIP])[:, None]
    Rrel = rel @ Rs.transpose(0, 2, 1)
    rs = r_shape * np.sqrt(w_shape)[..., None]
    c = np.zeros(NUM_JOINTS)
    c[[_LHIP, _RHIP]] = 0.5
    # camera (rotation) part: d(q R rel)/d omega = -q [R rel]x
    Jsc = -_skew(Rrel) * (ws * qs[:, None])[..., None, None]  # (S, 23, 3, 3)
    Hcc_rot = np.zeros((p.V, 3, 3))
    _scatter_blocks(Hcc_rot, sv, np.einsum("skri,skrj->sij", Jsc, Jsc))
    Hcc[:, nf : nf + 3, nf : nf + 3] += Hcc_rot
    gc_rot = np.zeros((p.V, 3))
    _scatter_blocks(gc_rot, sv, np.einsum("skri,skr->si", Jsc, rs))
    gc[:, nf : nf + 3] += gc_rot
    w2 = (ws * qs[:, None]) ** 2
    sw2 = w2.sum(1)
    M = (np.eye(NUM_JOINTS)[None] * w2[:, :, None] - c[None, :, None] * w2[:, None, :] - w2[:, :, None] * c[None, None, :]
         + sw2[:, None, None] * np.outer(c, c)[None])  # (S, 23, 23) = D^T W^2 D
    M_group = np.zeros((p.G, NUM_JOINTS, NUM_JOINTS))
    _scatter_blocks(M_group, p.s_group, M)
    for axis in range(3):  # M kron I_3
        Hpp_joints[:, :, axis, :, axis] += M_group
    y = (ws * qs[:, None])[..., None] * (rs @ Rs)  # w_k q R^T r_k
    _scatter_blocks(gp, p.s_group, (y - c[None, :, None] * y.sum(1, keepdims=True)).reshape(S, J3))
    Z = (ws * qs[:, None])[..., None, None] * np.einsum("skri,sra->skia", Jsc, Rs)  # Jsc_k^T w_k q R
    cross = Z - c[None, :, None, None] * Z.sum(1, keepdims=True)  # (S, 23(m), 3(i), 3(a))
    Hcp_rot = np.zeros((p.G, p.V, 3, J3))
    _scatter_blocks(Hcp_rot.reshape(p.G * p.V, 3, J3), p.s_group * p.V + sv, cross.transpose(0, 2, 1, 3).reshape(S, 3, J3))
    Hcp[:, :, nf : nf + 3, :] += Hcp_rot

    return rel, Rrel, w2, ws, qs, rs


def _scale_terms(p: _Problem, r_scale, rel, Rrel, w2, ws, qs, rs, Hpp, gp, Hcp):
    """The groups' log scales: their row and column of Hpp (in place), gp and Hcp with their column added."""
    nc = _camera_params(p)
    J3 = 3 * NUM_JOINTS
    S = len(p.s_view)
    c = np.zeros(NUM_JOINTS)
    c[[_LHIP, _RHIP]] = 0.5
    # --- group scales (log q): d r_k / d log q = w_k q R rel_k; its cross term with the rotation vanishes
    # ((-q w [a]x)^T (q w a) = 0) and with the points it is q^2 (w_m^2 rel_m - c_m sum_k w_k^2 rel_k)
    jq = (ws * qs[:, None])[..., None] * Rrel  # (S, 23, 3)
    hqq = np.bincount(p.s_group, (jq**2).sum((1, 2)), minlength=p.G) + p.scale_w**2
    gq = np.bincount(p.s_group, (jq * rs).sum((1, 2)), minlength=p.G) + p.scale_w * r_scale
    wrel = w2[..., None] * rel  # (S, 23, 3), w2 includes q^2
    xq = np.zeros((p.G, J3))
    _scatter_blocks(xq, p.s_group, (wrel - c[None, :, None] * wrel.sum(1, keepdims=True)).reshape(S, J3))
    if not p.free_scale:
        hqq, gq, xq = np.ones(p.G), np.zeros(p.G), np.zeros((p.G, J3))
    Hpp[:, J3, :J3] = Hpp[:, :J3, J3] = xq
    Hpp[:, J3, J3] = hqq
    gp = np.concatenate([gp, gq[:, None]], axis=1)
    Hcp = np.concatenate([Hcp, np.zeros((p.G, p.V, nc, 1))], axis=3)

    return gp, Hcp


def _add_priors(p: _Problem, dlogf, r_prior, Hcc, gc) -> None:
    """Add the focal priors and the lens parameters' zero-mean priors (in place)."""
    nf = 1 if p.square else 2
    # --- focal priors
    for vv in range(p.V):
        if p.prior_w[vv] > 0:
            jf = p.prior_w[vv] / nf * dlogf[vv]
            Hcc[vv, :nf, :nf] += np.outer(jf, jf)
            gc[vv, :nf] += jf * r_prior[vv]
    if p.lens:  # zero-mean priors on the lens parameters: a diagonal term
        lens_rows = np.arange(nf + 6, nf + 10)
        Hcc[:, lens_rows, lens_rows] += p.lens_prior_w**2
        gc[:, lens_rows] += r_prior[p.V:].reshape(p.V, -1) * p.lens_prior_w


def _hold_fixed(Hcc, gc, Hcp, free_cam):
    """Take the fixed camera parameters (``~free_cam`` (V, nc)) out: identity rows in Hcc (a copy), zeros in gc and
    Hcp (in place)."""
    Hcc[~free_cam] = 0.0
    Hcc = Hcc.copy()
    for vv in range(len(Hcc)):
        fixed = ~free_cam[vv]
        Hcc[vv][:, fixed] = 0.0
        Hcc[vv][fixed, fixed] = 1.0
    gc[~free_cam] = 0.0
    Hcp[:, ~free_cam] = 0.0
    return Hcc


def _arrow(Hcc, Hcp, Hpp, gc, gp) -> ArrowSystem:
    """The normal equations as the engine's arrow: the cameras (V nc) global, one block per group (3J + 1)."""
    V, nc = gc.shape
    G, m = gp.shape
    as_torch = torch.from_numpy
    return ArrowSystem(as_torch(block_diag(*Hcc)) if V else torch.zeros(0, 0, dtype=torch.float64),
                       as_torch(Hpp), as_torch(Hcp.reshape(G, V * nc, m).transpose(0, 2, 1)),
                       as_torch(gc.reshape(V * nc)), as_torch(gp))


def _solve(Hcc, Hcp, Hpp, gc, gp, lam):
    """The damped Gauss-Newton step (:func:`humancal.least_squares.solve_damped`): camera step (V, nc), point step
    (G, 23, 3), log-scale step (G,), and the damped reduced camera system S (V nc, V nc).

    Raises:
        np.linalg.LinAlgError: the damped system is not positive definite.
    """
    V, nc = gc.shape
    G = gp.shape[0]
    step = solve_damped(_arrow(Hcc, Hcp, Hpp, gc, gp), lam)
    if not bool(step.solved.all()):
        raise np.linalg.LinAlgError("bundle adjustment: the damped system is not positive definite")
    dp = step.block_step.numpy()
    return (step.global_step.numpy().reshape(V, nc), dp[:, :-1].reshape(G, NUM_JOINTS, 3), dp[:, -1],
            step.reduced.numpy())
