"""Camera translations and focal lengths from people's root positions (a linear multi-view solve).

Root positions: each detection's lifted pose is already in its camera's frame, so only its translation is
unknown: ``x_j ~ K (J_j + T)`` for the joints ``j`` is linear in ``T`` (a translation-only PnP, solved by
iteratively reweighted least squares on the rays). ``T_z`` comes from the body's metric size and scales with
the focal length, while ``T_x, T_y`` do not (``T_x = (x - c_x) T_z / f``): with ``zeta = T_z / f`` fixed by
the image, a detection's root is ``T(f) = (T_x, T_y, f zeta)``, *linear in f*.

Two detections ``(a, i)``, ``(b, j)`` of one person in one frame put the same world point at
``R_a^T (T_a(f_a) - t_a) = R_b^T (T_b(f_b) - t_b)``: linear in the focal lengths and translations once the
rotations are known. Stacked over all candidate pairs of all view pairs (camera 0 at the origin), with weak
priors on the focal lengths (the single-view estimates, weighted by their uncertainty), this is one sparse
linear least-squares problem, solved with Cauchy-reweighting so that wrongly matched pairs drop out. Where
views look at the people from different directions, one view's depth (focal-dependent) is another's lateral
position (focal-free), which fixes the focal lengths; a uniform body-size error only scales the scene.

A lifter does not know a person's size, though, and a per-person size error puts all of that person's roots too
far or too near by one factor; in the regressors it attenuates the focal lengths (errors in variables). By
default every pair therefore also gets a size factor (:func:`solve_focals_translations`, ``person_scale_std``),
which makes the problem bilinear: it is finished by Gauss-Newton from the linear solution.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from humancal.calibration.translation_pairs import conditioned_system, focal_stds, pair_system, reweighted_passes
from humancal.calibration.types import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = [
    "RootPositions",
    "root_positions",
    "FocalTranslationSolution",
    "solve_focals_translations",
    "resect_focal_translation",
]


@dataclass(frozen=True)
class RootPositions:
    """Root (hip midpoint) of every detection in its camera frame.

    Attributes:
        T_cam_m: (D, 3) root positions for the focal used, metres (NaN where unsolvable).
        zeta_m_per_px: (D,) ``T_z / f``: depth per pixel of focal length, metres per pixel.
        rms_px: (D,) RMS reprojection residual of the joints, pixels.
    """

    T_cam_m: np.ndarray
    zeta_m_per_px: np.ndarray
    rms_px: np.ndarray

    def at_focal(self, rows: np.ndarray, focal_px: np.ndarray) -> np.ndarray:
        """(M, 3) roots of ``rows`` for other focal lengths (``focal_px`` (M,)): depth rescaled, lateral kept."""
        T = self.T_cam_m[rows].copy()
        T[:, 2] = self.zeta_m_per_px[rows] * focal_px
        return T


def root_positions(
    detections: DenseDetections,
    lifted: LiftedPoses,
    K_per_view: np.ndarray,
    *,
    min_score: float = 0.2,
    min_joints: int = 4,
    iterations: int = 3,
) -> RootPositions:
    """Translation-only PnP of every detection's lifted pose.

    Args:
        detections: D detections.
        lifted: their lifted poses (camera frame, root-relative, metres; invalid rows give NaN roots).
        K_per_view: (V, 3, 3) intrinsics.
        min_score: joints below this 2D confidence are ignored.
        min_joints: fewer usable joints leave the root NaN.
        iterations: reweighting passes (Huber at 5 % of the person's image size).

    Returns:
        :class:`RootPositions`.
    """
    K = np.asarray(K_per_view, dtype=np.float64)[detections.view]  # (D, 3, 3)
    f = K[:, [0, 1], [0, 1]]  # (D, 2)
    c = K[:, :2, 2]
    u = (detections.keypoints_px - c[:, None]) / f[:, None]  # (D, J, 2) normalised rays
    valid = (detections.scores >= min_score) & np.isfinite(u).all(-1) & lifted.valid[:, None]
    J = np.nan_to_num(lifted.joints_cam_m)
    u = np.nan_to_num(u)
    w = np.where(valid, detections.scores, 0.0)
    size_px = np.nanmax(np.linalg.norm(detections.keypoints_px - np.nanmean(detections.keypoints_px, 1, keepdims=True),
                                       axis=-1), axis=1)
    T = np.full((len(J), 3), np.nan)
    for _ in range(iterations):
        # rows: (J_x + T_x) - u_x (J_z + T_z) = 0 and the same for y; normal equations written out
        ux, uy = u[..., 0], u[..., 1]
        bx, by = ux * J[..., 2] - J[..., 0], uy * J[..., 2] - J[..., 1]
        sw = w.sum(1)
        AtA = np.zeros((len(J), 3, 3))
        AtA[:, 0, 0] = AtA[:, 1, 1] = sw
        AtA[:, 0, 2] = AtA[:, 2, 0] = -(w * ux).sum(1)
        AtA[:, 1, 2] = AtA[:, 2, 1] = -(w * uy).sum(1)
        AtA[:, 2, 2] = (w * (ux**2 + uy**2)).sum(1)
        Atb = np.stack([(w * bx).sum(1), (w * by).sum(1), -(w * (ux * bx + uy * by)).sum(1)], -1)
        ok = (valid.sum(1) >= min_joints) & (np.linalg.det(AtA) > 1e-12)
        T[:] = np.nan
        T[ok] = np.linalg.solve(AtA[ok], Atb[ok][..., None])[..., 0]
        P = J + T[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            proj = P[..., :2] / P[..., 2:3]
        res_px = np.linalg.norm((proj - u) * f[:, None], axis=-1)
        huber = np.clip(0.05 * size_px[:, None] / np.maximum(res_px, 1e-9), None, 1.0)
        w = np.where(valid, detections.scores * np.nan_to_num(huber), 0.0)
    rms = np.sqrt(np.nansum(np.where(valid, res_px**2, 0.0), 1) / np.maximum(valid.sum(1), 1))
    T[T[:, 2] <= 0] = np.nan  # a root behind the camera is a failed fit
    return RootPositions(T, T[:, 2] / f[:, 0], np.where(np.isfinite(T[:, 0]), rms, np.nan))


@dataclass(frozen=True)
class FocalTranslationSolution:
    """Result of :func:`solve_focals_translations`.

    Attributes:
        focal_px: (V,) focal lengths, pixels.
        t_cam_from_world_m: (V, 3) translations (camera 0 at the origin), metres.
        residual_m: (M,) world distance between the two roots of each pair (after its size correction), metres.
        inlier: (M,) pairs consistent with the solution.
        focal_rel_std: (V,) relative standard deviation of each focal from the normal equations.
        focal_rel_std_data: (V,) the same without the focal priors: how much the pairs alone say (``inf``-like
            large values flag a focal the pairs cannot see, e.g. a camera looking straight down).
        pair_scale: (M,) the size correction of each pair's person (1 where not estimated or not finite).
    """

    focal_px: np.ndarray
    t_cam_from_world_m: np.ndarray
    residual_m: np.ndarray
    inlier: np.ndarray
    focal_rel_std: np.ndarray
    focal_rel_std_data: np.ndarray
    pair_scale: np.ndarray | None = None


def solve_focals_translations(
    roots: RootPositions,
    view: np.ndarray,
    rows_a: np.ndarray,
    rows_b: np.ndarray,
    R_cam_from_world: np.ndarray,
    focal_prior_px: np.ndarray,
    focal_prior_rel_std: np.ndarray,
    *,
    depth_rel_std: float = 0.05,
    floor_std_m: float = 0.05,
    iterations: int = 8,
    inlier_sigma: float = 3.0,
    person_scale_std: float | None = 0.1,
) -> FocalTranslationSolution:
    """Joint solve of all focal lengths and translations from candidate cross-view pairs.

    With ``person_scale_std`` (the default), every pair also gets an unknown size correction ``s`` of its
    person: a lifter sees body proportions, not body size, so a person's roots are all too far (or too near) by
    the same factor in every view. That per-person error is shared by both roots of a pair, and left in the
    regressors it attenuates the focal lengths (errors in variables: the people's depths spread by only about
    10 % of their distance, comparable to the spread of adult heights). The pair constraint becomes
    ``s (R_a^T T_a(f_a) - R_b^T T_b(f_b)) = R_a^T t_a - R_b^T t_b``, bilinear; it is solved by Gauss-Newton
    (the per-pair scales eliminated by a Schur complement), started from the linear solution at ``s = 1``, with
    a prior ``log s ~ N(0, person_scale_std^2)`` that also fixes the overall scale. ``None`` (or 0) gives the
    purely linear solve with ``s = 1``.

    Args:
        roots: root positions of all detections (any focal; only ``zeta`` and the lateral part are used).
        view: (D,) view of every detection.
        rows_a, rows_b: (M,) candidate pairs (same frame, different views), detection rows.
        R_cam_from_world: (V, 3, 3) rotations (camera 0 = identity).
        focal_prior_px: (V,) prior focal lengths, pixels.
        focal_prior_rel_std: (V,) their relative std (``inf`` for none).
        depth_rel_std: relative std of a root's depth (besides the per-person size), scales each pair's weight.
        floor_std_m: std added to every root, metres.
        iterations: Cauchy reweighting passes (each with one Gauss-Newton step when the scales are estimated).
        inlier_sigma: pairs within this many standard deviations are inliers.
        person_scale_std: prior std of the log size correction of each pair's person (None: no correction).

    Returns:
        :class:`FocalTranslationSolution`.
    """
    V = len(R_cam_from_world)
    system = pair_system(roots, view, rows_a, rows_b, R_cam_from_world, focal_prior_px, focal_prior_rel_std,
                         depth_rel_std, floor_std_m)
    M, sigma = system.M, system.sigma
    conditioned = conditioned_system(system, V)
    scaled = bool(person_scale_std) and M > 0
    prior_s = 1.0 / person_scale_std**2 if scaled else 0.0
    # stage 1: s = 1, linear, Cauchy-reweighted (finds grossly wrong pairs); stage 2 (scales estimated): Gauss-Newton
    # steps from the stage-1 solution over the stage-1 inliers, Cauchy-reweighted with a robust (median) residual
    # scale: without the per-person size error the roots agree far better than ``sigma`` says
    state = reweighted_passes(system, conditioned, 1.0 / sigma, None, np.zeros(M), iterations)
    stage1_inlier = np.ones(M, bool)
    if scaled:
        stage1_inlier = state.r_norm < inlier_sigma
        if stage1_inlier.sum() >= 2:  # else nothing to refine: keep the linear solution
            refined = reweighted_passes(system, conditioned, np.where(stage1_inlier, 1.0 / sigma, 0.0), state.y,
                                        state.log_q, iterations, prior_s, stage1_inlier)
            if np.isfinite(refined.y).all() and np.isfinite(refined.log_q).all():
                state = refined
            else:  # a degenerate pair set: fall back on the linear solution at s = 1
                state = replace(state, log_q=np.zeros(M), x=system.col_scale @ state.y)
    residual_m = np.linalg.norm(state.res_m, axis=1)
    focal = state.x[:V]
    t = state.x[V:].reshape(V, 3)
    f_std, f_std_data = focal_stds(state.reduced_data, conditioned.E_normal, conditioned.gauge, system.col_scale,
                                   focal)
    residual = np.full(len(rows_a), np.nan)
    residual[system.ok] = residual_m
    inlier = np.zeros(len(rows_a), bool)
    inlier[system.ok] = (state.r_norm < inlier_sigma) & stage1_inlier
    pair_scale = np.ones(len(rows_a))
    pair_scale[system.ok] = np.exp(-state.log_q)
    return FocalTranslationSolution(focal, t, residual, inlier, f_std, f_std_data, pair_scale)


def resect_focal_translation(
    points_world_m: np.ndarray,
    points_px: np.ndarray,
    weights: np.ndarray,
    R_cam_from_world: np.ndarray,
    principal_point_px: np.ndarray,
    *,
    iterations: int = 5,
    huber_rel: float = 0.01,
) -> tuple[float, np.ndarray, float]:
    """Focal length and translation of one camera of known rotation from 2D-3D correspondences (linear).

    ``x - c = f P_xy / P_z`` with ``P = R X + t`` is linear in ``(f, f t_x, f t_y, t_z)``; solved by weighted
    least squares with Huber reweighting on the pixel residuals. It needs the points at different depths
    (perspective), which is what separates the focal length from the distance.

    Args:
        points_world_m: (N, 3) world points.
        points_px: (N, 2) their images, pixels.
        weights: (N,) confidences.
        R_cam_from_world: (3, 3) the camera's rotation.
        principal_point_px: (2,) principal point.
        iterations: reweighting passes.
        huber_rel: Huber threshold as a fraction of the image spread of the points.

    Returns:
        focal_px, t_cam_from_world_m (3,), rms_px over the inliers (NaN focal when fewer than 3 points).
    """
    X = np.asarray(points_world_m, dtype=np.float64)
    x = np.asarray(points_px, dtype=np.float64) - principal_point_px
    w = np.asarray(weights, dtype=np.float64).copy()
    ok = np.isfinite(X).all(1) & np.isfinite(x).all(1) & (w > 0)
    X, x, w = X[ok], x[ok], w[ok]
    if len(X) < 3:
        return float("nan"), np.full(3, np.nan), float("nan")
    RX = X @ np.asarray(R_cam_from_world).T
    n = len(X)
    A = np.zeros((2 * n, 4))
    b = np.zeros(2 * n)
    # x (RX_z + t_z) = f RX_x + f t_x  ->  [RX_x, 1, 0, -x] . [f, f t_x, f t_y, t_z] = x RX_z
    A[0::2, 0], A[0::2, 1], A[0::2, 3] = RX[:, 0], 1.0, -x[:, 0]
    A[1::2, 0], A[1::2, 2], A[1::2, 3] = RX[:, 1], 1.0, -x[:, 1]
    b[0::2], b[1::2] = x[:, 0] * RX[:, 2], x[:, 1] * RX[:, 2]
    threshold = huber_rel * float(np.ptp(x, axis=0).max() or 1.0)
    sol = np.zeros(4)
    res = np.zeros(n)
    for _ in range(iterations):
        sw = np.repeat(np.sqrt(w), 2)
        sol = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)[0]
        with np.errstate(invalid="ignore", divide="ignore"):  # a zero focal is refused after the loop
            f, t = sol[0], np.array([sol[1] / sol[0], sol[2] / sol[0], sol[3]])
            P = RX + t
            res = np.linalg.norm(f * P[:, :2] / P[:, 2:3] - x, axis=1)
        res = np.where(P[:, 2] > 0, res, np.inf)
        if not (np.isfinite(sol).all() and sol[0] > 0):  # no focal: refused below, no NaN weights into LAPACK
            break
        # algebraic rows are pixel errors times the depth: divide it out, then Huber
        w = np.asarray(weights, dtype=np.float64)[ok] / np.maximum(P[:, 2], 1e-3) ** 2
        w *= np.minimum(1.0, threshold / np.maximum(res, 1e-9))
    # the linear rows carry the pixel noise in the design matrix (biased): finish on the pixel residuals
    w0 = np.sqrt(np.asarray(weights, dtype=np.float64)[ok])
    if not (np.isfinite(sol).all() and sol[0] > 0):
        return float("nan"), np.full(3, np.nan), float("nan")

    def residual(p):
        P = RX + p[1:]
        z = np.maximum(P[:, 2], 1e-3)
        # a trial step far out (log focal beyond +-30) is a bad step, not an overflow warning
        return ((np.exp(np.clip(p[0], -30.0, 30.0)) * P[:, :2] / z[:, None] - x) * w0[:, None]).ravel()

    fit = least_squares(residual, np.r_[np.log(sol[0]), t], loss="huber", f_scale=threshold, x_scale="jac")
    f, t = float(np.exp(fit.x[0])), fit.x[1:]
    res = np.linalg.norm(fit.fun.reshape(-1, 2), axis=1) / np.maximum(w0, 1e-9)
    inl = res < 3 * threshold
    rms = float(np.sqrt(np.mean(res[inl] ** 2))) if inl.any() else float("nan")
    return f, t, rms
