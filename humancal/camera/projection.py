"""Projection of world points through OpenCV cameras with lens distortion, in torch and numpy.

The model is OpenCV's (``cv2.projectPoints``) with the five coefficients ``(k1, k2, p1, p2, k3)``
(``docs/conventions.md``): with ``(x, y) = (X / Z, Y / Z)`` in the camera frame and ``r2 = x^2 + y^2``,

    x' = x (1 + k1 r2 + k2 r2^2 + k3 r2^3) + 2 p1 x y + p2 (r2 + 2 x^2)
    y' = y (1 + k1 r2 + k2 r2^2 + k3 r2^3) + p1 (r2 + 2 y^2) + 2 p2 x y
    (u, v) = K[:2, :2] @ (x', y') + (cx, cy)

Shapes broadcast like batched matrices: cameras carry a leading batch ``*C`` (``()`` for one camera, ``(V,)``
for a rig) and points ``(*B, N, 3)``; the result has the batch ``broadcast(*B, *C)``. So ``(N, 3)`` points through
a ``(V,)`` rig give ``(V, N, 2)`` pixels, and per-view points ``(..., V, N, 3)`` give ``(..., V, N, 2)``.
One implementation (torch); the numpy form runs it in float64 without gradients.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

__all__ = ["project_points_torch", "project_points_np", "undistort_points_px", "MIN_DEPTH_M"]

MIN_DEPTH_M = 1e-6
"""Points nearer to the camera plane than this (or behind it), metres, are not projected."""


def _check(points: Tensor, K: Tensor, R: Tensor, t: Tensor, distortion: Tensor | None) -> None:
    if points.ndim < 2 or points.shape[-1] != 3:
        raise ValueError(f"points_world_m must have shape (..., N, 3), got {tuple(points.shape)}")
    batch = K.shape[:-2]
    expected = {"K": (K, (3, 3)), "R_cam_from_world": (R, (3, 3)), "t_cam_from_world_m": (t, (3,))}
    if distortion is not None:
        expected["distortion"] = (distortion, (5,))
    for name, (value, tail) in expected.items():
        if tuple(value.shape) != tuple(batch) + tail:
            raise ValueError(f"{name} must have shape {tuple(batch) + tail} (camera batch {tuple(batch)} of K), "
                             f"got {tuple(value.shape)}")


def project_points_torch(
    points_world_m: Tensor,
    K: Tensor,
    R_cam_from_world: Tensor,
    t_cam_from_world_m: Tensor,
    distortion: Tensor | None = None,
) -> tuple[Tensor, Tensor, Tensor]:
    """Project world points to pixels through OpenCV cameras with distortion (differentiable).

    Args:
        points_world_m: (*B, N, 3) points in the world frame, metres.
        K: (*C, 3, 3) intrinsic matrices, pixels.
        R_cam_from_world: (*C, 3, 3) rotations, world to camera.
        t_cam_from_world_m: (*C, 3) translations, metres.
        distortion: (*C, 5) OpenCV coefficients ``(k1, k2, p1, p2, k3)``; None for an ideal pinhole.

    Returns:
        pixels_px: (*batch, N, 2) image coordinates, pixels, ``batch = broadcast(B, C)``; finite everywhere
            (where not ``in_front`` they are computed at depth ``MIN_DEPTH_M`` and mean nothing), so that
            gradients stay finite when the caller masks them out.
        depth_m: (*batch, N) depth along the optical axis, metres.
        in_front: (*batch, N) bool, depth >= ``MIN_DEPTH_M``.

    Raises:
        ValueError: shapes that do not fit.
    """
    _check(points_world_m, K, R_cam_from_world, t_cam_from_world_m, distortion)
    # (*B, N, 3) @ (*C, 3, 3)^T: the camera batch lines up with the points' leading batch (matmul broadcasting)
    x_cam = torch.matmul(points_world_m, R_cam_from_world.transpose(-1, -2)) + t_cam_from_world_m.unsqueeze(-2)
    depth = x_cam[..., 2]
    in_front = depth >= MIN_DEPTH_M
    safe_depth = torch.where(in_front, depth, torch.full_like(depth, MIN_DEPTH_M))
    xy = x_cam[..., :2] / safe_depth.unsqueeze(-1)
    if distortion is not None:
        d = distortion.unsqueeze(-2)  # (*C, 1, 5) against (*batch, N)
        k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy = torch.stack(
            [x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
             y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y],
            dim=-1,
        )
    pixels = torch.matmul(xy, K[..., :2, :2].transpose(-1, -2)) + K[..., :2, 2].unsqueeze(-2)
    return pixels, depth, in_front


def project_points_np(
    points_world_m: np.ndarray,
    K: np.ndarray,
    R_cam_from_world: np.ndarray,
    t_cam_from_world_m: np.ndarray,
    distortion: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_points_torch` on numpy arrays, float64, with NaN pixels where a point is not in front.

    Args:
        points_world_m: (*B, N, 3) world points, metres.
        K: (*C, 3, 3) intrinsics, pixels.
        R_cam_from_world: (*C, 3, 3).
        t_cam_from_world_m: (*C, 3), metres.
        distortion: (*C, 5) ``(k1, k2, p1, p2, k3)`` or None.

    Returns:
        pixels_px: (*batch, N, 2), NaN where the point is not in front of the camera (or is NaN).
        depth_m: (*batch, N), metres.

    Raises:
        ValueError: shapes that do not fit.
    """
    as_t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))  # noqa: E731
    with torch.no_grad():
        px, depth, in_front = project_points_torch(
            as_t(points_world_m), as_t(K), as_t(R_cam_from_world), as_t(t_cam_from_world_m),
            None if distortion is None else as_t(distortion),
        )
    px = px.numpy()
    px[~in_front.numpy()] = np.nan
    return px, depth.numpy()


def undistort_points_px(points_px: np.ndarray, K: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Pixels of a distorting lens moved to where the same camera without distortion (same ``K``) sees them:
    the inverse of the distortion of :func:`project_points_np` (OpenCV's iterative ``undistortPoints``).

    Args:
        points_px: (N, 2) observed pixels (NaN rows stay NaN).
        K: (3, 3) intrinsics, pixels.
        distortion: (5,) ``(k1, k2, p1, p2, k3)``.

    Returns:
        (N, 2) undistorted pixels.
    """
    import cv2

    points = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    out = np.full_like(points, np.nan)
    finite = np.isfinite(points).all(1)
    if finite.any():
        K = np.asarray(K, dtype=np.float64)
        moved = cv2.undistortPoints(points[finite].reshape(-1, 1, 2), K, np.asarray(distortion, np.float64), P=K,
                                    criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9))
        out[finite] = moved.reshape(-1, 2)
    return out
