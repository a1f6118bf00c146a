"""Multi-view triangulation of 2D keypoints with known cameras.

The linear (DLT) solution is computed in normalized image coordinates (pixels mapped through
K^-1), where the rows of the homogeneous system are well conditioned, and each view's rows are
weighted by the detection confidence. One optional robust pass drops, per point, the views whose
reprojection error exceeds a threshold and solves again.

Example: two cameras 90 degrees apart place a point exactly from its two pixels:

    >>> import numpy as np
    >>> from humancal.camera import Camera, CameraRig, project_points
    >>> from humancal.geometry.triangulation import triangulate_dlt
    >>> K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    >>> front = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])   # looking along +y
    >>> side = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])   # looking along -x
    >>> cameras = CameraRig.from_cameras([Camera.from_center(K, front, [0.0, -4.0, 1.0], 640, 480),
    ...                                   Camera.from_center(K, side, [4.0, 0.0, 1.0], 640, 480)])
    >>> point = np.array([[0.2, 0.1, 1.5]])
    >>> pixels = np.stack([project_points(c, point)[0] for c in cameras])   # (views, points, 2)
    >>> points, views = triangulate_dlt(cameras, pixels, np.ones((2, 1)))
    >>> points.round(6).tolist(), views.tolist()
    ([[0.2, 0.1, 1.5]], [2])
"""

from __future__ import annotations

import numpy as np

from humancal.camera import CameraRig, project_points

__all__ = ["triangulate_dlt", "reprojection_errors_px"]


def triangulate_dlt(
    cameras: CameraRig,
    points_px: np.ndarray,
    weights: np.ndarray,
    *,
    min_views: int = 2,
    outlier_threshold_px: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Confidence-weighted DLT triangulation of many points at once.

    Args:
        cameras: the rig of V cameras (distortion is ignored: undistort detections first if it matters).
        points_px: (V, N, 2) pixel coordinates of N points in each view (any value where missing).
        weights: (V, N) non-negative confidences; 0 marks a missing observation.
        min_views: a point needs observations with weight > 0 in at least this many views.
        outlier_threshold_px: when given, while a point's worst view reprojects farther than this,
            that view is dropped and the point solved again (never below ``min_views`` views).

    Returns:
        points_world_m: (N, 3) triangulated points, world frame, metres (NaN where not solvable).
        n_views: (N,) number of views used per point.

    Raises:
        ValueError: shapes disagree with the number of cameras, or weights are negative / NaN.
    """
    V = len(cameras)
    points_px = np.asarray(points_px, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if points_px.ndim != 3 or points_px.shape[0] != V or points_px.shape[2] != 2:
        raise ValueError(f"points_px must have shape (V={V}, N, 2), got {points_px.shape}")
    if weights.shape != points_px.shape[:2]:
        raise ValueError(f"weights must have shape {points_px.shape[:2]}, got {weights.shape}")
    if np.isnan(weights).any() or (weights < 0).any():
        raise ValueError("weights must be finite and non-negative (0 marks a missing observation)")
    weights = np.where(np.isfinite(points_px).all(-1), weights, 0.0)

    X, n_views = _solve(cameras, points_px, weights, min_views)
    if outlier_threshold_px is None:
        return X, n_views
    # Drop the worst view of every point that reprojects beyond the threshold, solve again, repeat:
    # a single wrong observation (a left-right flip) spreads its error over all views of the first
    # solution, so removing views one at a time is what isolates it.
    weights = weights.copy()
    for _ in range(V - min_views):
        err = reprojection_errors_px(cameras, X, points_px)
        err = np.where(weights > 0, np.nan_to_num(err, nan=np.inf), -np.inf)
        worst = err.argmax(0)
        redo = (err.max(0) > outlier_threshold_px) & (n_views > min_views)
        if not redo.any():
            break
        weights[worst[redo], np.nonzero(redo)[0]] = 0.0
        X[redo], n_views[redo] = _solve(cameras, points_px[:, redo], weights[:, redo], min_views)
    return X, n_views


def _solve(
    cameras: CameraRig, points_px: np.ndarray, weights: np.ndarray, min_views: int
) -> tuple[np.ndarray, np.ndarray]:
    V, N = weights.shape
    A = np.zeros((N, 2 * V, 4))
    for v, cam in enumerate(cameras):
        K_inv = np.linalg.inv(cam.K)
        xn = np.nan_to_num(points_px[v]) @ K_inv[:2, :2].T + K_inv[:2, 2]
        Rt = np.hstack([cam.R_cam_from_world, cam.t_cam_from_world_m[:, None]])  # (3, 4)
        w = weights[v][:, None]
        A[:, 2 * v] = w * (xn[:, :1] * Rt[2] - Rt[0])
        A[:, 2 * v + 1] = w * (xn[:, 1:2] * Rt[2] - Rt[1])
    n_views = (weights > 0).sum(0)
    X = np.full((N, 3), np.nan)
    ok = n_views >= min_views
    if ok.any():
        # the right singular vector of A's smallest singular value is the eigenvector of A^T A's smallest
        # eigenvalue: a batched 4 x 4 symmetric eigenproblem costs a third of the batched SVD of A (2V x 4)
        A_ok = A[ok]
        _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", A_ok, A_ok))
        h = vectors[:, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            X[ok] = h[:, :3] / h[:, 3:4]
    return X, np.where(ok, n_views, 0)


def reprojection_errors_px(cameras: CameraRig, points_world_m: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """Pixel distance between projected 3D points and observed 2D points.

    Args:
        cameras: the rig of V cameras.
        points_world_m: (N, 3) world points (NaN allowed).
        points_px: (V, N, 2) observations (NaN allowed).

    Returns:
        (V, N) errors in pixels (NaN where either side is missing or the point is behind the camera).
    """
    out = np.full(points_px.shape[:2], np.nan)
    for v, cam in enumerate(cameras):
        px, _ = project_points(cam, points_world_m)
        out[v] = np.linalg.norm(px - points_px[v], axis=-1)
    return out
