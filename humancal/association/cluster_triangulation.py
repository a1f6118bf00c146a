"""Triangulation of the people the matching found: every cluster of every frame at once, in closed form.

The rule of :func:`humancal.geometry.triangulation.triangulate_dlt` (confidence-weighted DLT rows in normalised
coordinates; a joint's worst view dropped while it reprojects too far and more than two views remain), solved
for all joints of all clusters together: the 3 x 3 normal equations of each point in closed form, no SVD per
point (``triangulate_dlt`` on the 900-frame benchmark took about 5 s, this about 0.5 s). Lens distortion is
undone first with OpenCV.
"""

from __future__ import annotations

import cv2
import numpy as np

from humancal.camera import CameraRig
from humancal.keypoints import NUM_JOINTS
from humancal.tables.detections import DenseDetections

__all__ = ["cluster_observations", "normal_equations", "reprojection_errors_px", "triangulate_clusters", "undistorted_keypoints_px"]


def undistorted_keypoints_px(detections: DenseDetections, rig: CameraRig) -> np.ndarray:
    """(D, 23, 2) keypoints with the lens distortion undone (pixels of the ideal pinhole with the same K)."""
    kp = np.asarray(detections.keypoints_px, dtype=np.float64).copy()
    for v in np.flatnonzero(np.abs(rig.distortion).sum(1) > 0):
        rows = np.flatnonzero(detections.view == v)
        pts = kp[rows].reshape(-1, 1, 2)
        ok = np.isfinite(pts).all(-1)[:, 0]
        if ok.any():
            pts[ok] = cv2.undistortPoints(pts[ok], rig.K[v], rig.distortion[v], P=rig.K[v])
        kp[rows] = pts.reshape(len(rows), NUM_JOINTS, 2)
    return kp


def normal_equations(cameras: list, points_px: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 3 x 3 normal equations ``A X = b`` of the confidence-weighted DLT of every point (the rows of
    :func:`~humancal.geometry.triangulation.triangulate_dlt`, homogeneous coordinate fixed to 1), in closed form.

    A view's two rows are ``w (x P2 - P0)`` and ``w (y P2 - P1)`` with ``P = [R | t]`` and (x, y) the normalised
    image point: at a point of depth z their residuals are z times the normalised reprojection error.

    Args:
        cameras: V pinhole cameras (no distortion).
        points_px: (V, N, 2) pixels (any value where the weight is 0).
        weights: (V, N) row weights, 0 where missing.

    Returns:
        A: (N, 3, 3) and b: (N, 3); the DLT's least-squares point solves ``A X = b``.
    """
    V, N = weights.shape
    K_inv = np.linalg.inv(np.stack([c.K for c in cameras]))
    Rt = np.stack([np.hstack([c.R_cam_from_world, c.t_cam_from_world_m[:, None]]) for c in cameras])  # (V, 3, 4)
    u, v = np.nan_to_num(points_px[..., 0]), np.nan_to_num(points_px[..., 1])
    x = K_inv[:, None, 0, 0] * u + K_inv[:, None, 0, 1] * v + K_inv[:, None, 0, 2]
    y = K_inv[:, None, 1, 1] * v + K_inv[:, None, 1, 2]
    # The rows summed as outer products:
    # w^2 ((x^2 + y^2) P2 P2^T - x (P2 P0^T + P0 P2^T) - y (P2 P1^T + P1 P2^T) + P0 P0^T + P1 P1^T);
    # the four coefficients of every point and view times the views' constant 4x4 terms: one matrix product.
    w2 = weights * weights
    coef = np.stack([w2 * (x * x + y * y), -w2 * x, -w2 * y, w2], -1)  # (V, N, 4)
    P0, P1, P2 = Rt[:, 0], Rt[:, 1], Rt[:, 2]
    outer = lambda a, b: a[:, :, None] * b[:, None, :]  # noqa: E731
    basis = np.stack([outer(P2, P2), outer(P2, P0) + outer(P0, P2), outer(P2, P1) + outer(P1, P2),
                      outer(P0, P0) + outer(P1, P1)], 1)  # (V, 4, 4, 4)
    M = (coef.transpose(1, 0, 2).reshape(N, 4 * V) @ basis.reshape(4 * V, 16)).reshape(N, 4, 4)
    return M[:, :3, :3], -M[:, :3, 3]


def reprojection_errors_px(cameras: list, points_world_m: np.ndarray, points_px: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """(V, N) reprojection errors of (N, 3) finite points against (V, N, 2) pixels (NaN where the pixel is; inf
    behind a camera), and (V, N) the points' depths in each camera, metres."""
    K = np.stack([c.K for c in cameras])
    Rt = np.stack([np.hstack([c.R_cam_from_world, c.t_cam_from_world_m[:, None]]) for c in cameras])
    cam = np.swapaxes(Rt[:, :, :3] @ points_world_m.T, 1, 2) + Rt[:, None, :, 3]  # (V, N, 3)
    depth = cam[..., 2]
    front = depth > 0
    safe = np.where(front, depth, 1.0)
    xc, yc = cam[..., 0] / safe, cam[..., 1] / safe
    du = K[:, None, 0, 0] * xc + K[:, None, 0, 1] * yc + K[:, None, 0, 2] - points_px[..., 0]
    dv = K[:, None, 1, 1] * yc + K[:, None, 1, 2] - points_px[..., 1]
    return np.where(front, np.sqrt(du * du + dv * dv), np.inf), depth


def _linear_points(cameras: list, points_px: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The confidence-weighted DLT of every point, solved in closed form (no per-point decomposition).

    Args:
        cameras: V pinhole cameras (no distortion).
        points_px: (V, N, 2) pixels (any value where the weight is 0).
        weights: (V, N) confidences, 0 where missing.

    Returns:
        points_world_m: (N, 3), NaN with fewer than 2 views or a singular system; errors_px: (V, N), NaN where
        missing.
    """
    A, b = normal_equations(cameras, points_px, weights)
    cof = np.stack([np.cross(A[:, 1], A[:, 2]), np.cross(A[:, 2], A[:, 0]), np.cross(A[:, 0], A[:, 1])], 1)
    det = np.einsum("ni,ni->n", A[:, 0], cof[:, 0])
    scale = np.abs(A).max((1, 2))
    ok = ((weights > 0).sum(0) >= 2) & (np.abs(det) > 1e-12 * np.maximum(scale, 1e-300) ** 3)
    X = np.full((len(A), 3), np.nan)
    X[ok] = (cof[ok] * b[ok, :, None]).sum(1) / det[ok, None]
    # Reprojection errors on a NaN-free copy (NaN slows the products down; those points are masked after).
    errors, _ = reprojection_errors_px(cameras, np.where(ok[:, None], X, 0.0), np.nan_to_num(points_px))
    errors[(weights <= 0) | ~ok[None]] = np.nan
    return X, errors


def cluster_observations(cluster: np.ndarray, n_clusters: int, view: np.ndarray, keypoints_px: np.ndarray,
                         scores: np.ndarray, num_views: int) -> tuple[np.ndarray, np.ndarray]:
    """The keypoints of every cluster in every view: (V, C, 23, 2) pixels (NaN where the view has no detection in
    the cluster) and (V, C, 23) confidences (0 there), from (D,) ``cluster`` (global cluster or -1), ``view`` and
    the (D, 23, 2) keypoints and (D, 23) scores of the detections."""
    points = np.full((num_views, n_clusters, NUM_JOINTS, 2), np.nan)
    weights = np.zeros((num_views, n_clusters, NUM_JOINTS))
    m = cluster >= 0
    points[view[m], cluster[m]] = keypoints_px[m]
    weights[view[m], cluster[m]] = scores[m]
    return points, weights


def triangulate_clusters(cluster: np.ndarray, n_clusters: int, view: np.ndarray, keypoints_px: np.ndarray,
                 scores: np.ndarray, cameras: list, threshold_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(C, 23, 3) joints and (C, 23) views used of clusters 0..C-1 (``cluster``: (D,) global cluster or -1).

    The rule of :func:`~humancal.geometry.triangulation.triangulate_dlt` (confidence-weighted DLT rows; while a
    joint's worst view reprojects farther than ``threshold_px`` and more than 2 views remain, that view is dropped
    and the joint solved again), with the closed-form solve of :func:`_linear_points` (the SVD per point and the
    reprojection through the generic projection cost ~10x more on the benchmark workload).
    """
    if n_clusters == 0:
        return np.zeros((0, NUM_JOINTS, 3)), np.zeros((0, NUM_JOINTS), np.int64)
    V = len(cameras)
    points, weights = cluster_observations(cluster, n_clusters, view, keypoints_px, scores, V)
    points, weights = points.reshape(V, -1, 2), weights.reshape(V, -1)
    X, errors = _linear_points(cameras, points, weights)
    redo = np.arange(X.shape[0])
    for _ in range(V - 2):
        worst = np.where(np.isnan(errors), -np.inf, errors)
        bad = (worst.max(0) > threshold_px) & ((weights[:, redo] > 0).sum(0) > 2)
        if not bad.any():
            break
        redo, errors = redo[bad], errors[:, bad]
        weights[np.argmax(np.where(np.isnan(errors), -np.inf, errors), 0), redo] = 0.0
        X[redo], errors = _linear_points(cameras, points[:, redo], weights[:, redo])
    used = np.where(np.isfinite(X).all(-1), (weights > 0).sum(0), 0)
    return X.reshape(n_clusters, NUM_JOINTS, 3), used.reshape(n_clusters, NUM_JOINTS).astype(np.int64)
