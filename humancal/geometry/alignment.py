"""Least-squares similarity and rigid alignment of corresponding point sets (Umeyama), over roma.

``fit_similarity`` returns the transform ``x -> scale * R @ x + t`` as a :class:`Similarity`; ``align_points``
applies the best one to the source directly, batched over many point sets with per-point weights (a weight of 0
leaves a point, even a NaN one, out of the fit). ``rigid_residual_rms_m`` gives only the residual of the best rigid
motion, for very many small point sets at once (closed form, no decomposition per set).

Example: the similarity between a square and the same square doubled and moved:

    >>> import numpy as np
    >>> from humancal.geometry.alignment import fit_similarity
    >>> square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    >>> found = fit_similarity(square, 2.0 * square + [0.0, 0.0, 3.0])
    >>> round(found.scale, 6), found.t.round(6).tolist(), np.allclose(found.R, np.eye(3))
    (2.0, [0.0, 0.0, 3.0], True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import roma
import torch

from humancal.camera import Camera

__all__ = ["Similarity", "fit_similarity", "align_points", "best_rotation_trace", "rigid_residual_rms_m"]


@dataclass(frozen=True)
class Similarity:
    """``x -> scale * R @ x + t``.

    Attributes:
        scale: positive scale.
        R: (3, 3) rotation.
        t: (3,) translation (in the target's unit).
    """

    scale: float
    R: np.ndarray
    t: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) transformed points."""
        return self.scale * np.asarray(points, dtype=np.float64) @ self.R.T + self.t

    def inverse(self) -> Similarity:
        """The transform taking the target back onto the source."""
        R_inv = self.R.T
        return Similarity(1.0 / self.scale, R_inv, -(R_inv @ self.t) / self.scale)

    def apply_to_camera(self, camera: Camera) -> Camera:
        """The same camera expressed in the target world (its image is unchanged; the translation scaled)."""
        R_new = camera.R_cam_from_world @ self.R.T
        return Camera(camera.K, R_new, -R_new @ self.apply(camera.center_world_m), camera.width_px,
                      camera.height_px, camera.distortion)


def _registration(src: torch.Tensor, dst: torch.Tensor, weights: torch.Tensor | None, with_scale: bool):
    if with_scale:
        return roma.rigid_points_registration(src, dst, weights=weights, compute_scaling=True)
    R, t = roma.rigid_points_registration(src, dst, weights=weights)
    return R, t, torch.ones(R.shape[:-2], dtype=R.dtype)


def fit_similarity(source: np.ndarray, target: np.ndarray, with_scale: bool = True) -> Similarity:
    """The least-squares similarity mapping ``source`` onto ``target`` (Umeyama 1991).

    Args:
        source, target: (N, 3) corresponding points, finite; N >= 3 and not collinear for a unique answer.
        with_scale: estimate the scale (else 1: a rigid motion).

    Returns:
        The :class:`Similarity`.

    Raises:
        ValueError: shapes differ, fewer than 2 points, non-finite values, or all source points equal.
    """
    src = np.asarray(source, dtype=np.float64)
    dst = np.asarray(target, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 2:
        raise ValueError(f"fit_similarity needs two (N>=2, 3) arrays of the same shape, got {src.shape} and "
                         f"{dst.shape}")
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        raise ValueError("fit_similarity: points must be finite")
    if not np.ptp(src, axis=0).any():
        raise ValueError("fit_similarity: the source points are all equal (no rotation or scale is defined)")
    R, t, s = _registration(torch.from_numpy(src), torch.from_numpy(dst), None, with_scale)
    return Similarity(float(s), R.numpy(), t.numpy())


def align_points(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None, with_scale: bool = True
) -> np.ndarray:
    """Each source point set moved by its best similarity (or rigid motion) onto the target, batched.

    Args:
        source, target: (..., N, 3) corresponding points; entries with weight 0 may be NaN.
        weights: (..., N) non-negative weights (default: 1 where both points are finite, else 0). A set needs
            at least three points of positive weight, not collinear, for a unique fit.
        with_scale: estimate a scale per set (else 1).

    Returns:
        (..., N, 3) aligned source points (every point of a set moved, weighted or not; NaN sets where fewer
        than 3 points have positive weight).

    Raises:
        ValueError: shapes differ or are not (..., N, 3), or weights of the wrong shape or negative.
    """
    src = np.asarray(source, dtype=np.float64)
    dst = np.asarray(target, dtype=np.float64)
    if src.shape != dst.shape or src.ndim < 2 or src.shape[-1] != 3:
        raise ValueError(f"align_points needs two (..., N, 3) arrays of the same shape, got {src.shape} and "
                         f"{dst.shape}")
    finite = np.isfinite(src).all(-1) & np.isfinite(dst).all(-1)
    w = finite.astype(np.float64) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != src.shape[:-1] or not (w >= 0).all():
        raise ValueError(f"align_points: weights must be non-negative with shape {src.shape[:-1]}, got {w.shape}")
    w = np.where(finite, w, 0.0)
    enough = (w > 0).sum(-1) >= 3
    w_safe = np.where(enough[..., None], w, 1.0)  # sets too small to fit get dummy weights, NaN results below
    src0, dst0 = np.where(finite[..., None], src, 0.0), np.where(finite[..., None], dst, 0.0)
    R, t, s = _registration(torch.from_numpy(src0), torch.from_numpy(dst0), torch.from_numpy(w_safe), with_scale)
    aligned = s.numpy()[..., None, None] * src @ np.swapaxes(R.numpy(), -1, -2) + t.numpy()[..., None, :]
    return np.where(enough[..., None, None], aligned, np.nan)


def _det3(M: np.ndarray) -> np.ndarray:
    """(...,) determinants of (..., 3, 3) matrices (elementwise: faster than LAPACK on many small ones)."""
    return (M[..., 0, 0] * (M[..., 1, 1] * M[..., 2, 2] - M[..., 1, 2] * M[..., 2, 1])
            - M[..., 0, 1] * (M[..., 1, 0] * M[..., 2, 2] - M[..., 1, 2] * M[..., 2, 0])
            + M[..., 0, 2] * (M[..., 1, 0] * M[..., 2, 1] - M[..., 1, 1] * M[..., 2, 0]))


def best_rotation_trace(M: np.ndarray) -> np.ndarray:
    """(...,) ``max_R trace(R^T M)`` over rotations for (..., 3, 3) ``M``: ``s1 + s2 + sign(det M) s3``.

    The singular values come from the closed-form eigenvalues of the symmetric ``M^T M`` (trigonometric solution
    of its characteristic cubic), so no per-matrix decomposition runs.
    """
    S = np.swapaxes(M, -1, -2) @ M
    q = np.trace(S, axis1=-2, axis2=-1) / 3.0
    off = S[..., 0, 1] ** 2 + S[..., 0, 2] ** 2 + S[..., 1, 2] ** 2
    p = np.sqrt(((S[..., 0, 0] - q) ** 2 + (S[..., 1, 1] - q) ** 2 + (S[..., 2, 2] - q) ** 2 + 2.0 * off) / 6.0)
    safe_p = np.where(p > 0, p, 1.0)
    Bm = (S - q[..., None, None] * np.eye(3)) / safe_p[..., None, None]
    r = np.clip(_det3(Bm) / 2.0, -1.0, 1.0)
    phi = np.arccos(r) / 3.0
    e1 = q + 2.0 * p * np.cos(phi)
    e3 = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    e2 = 3.0 * q - e1 - e3
    singular = np.sqrt(np.maximum(np.stack([e1, e2, e3], -1), 0.0))
    sign = np.where(_det3(M) < 0, -1.0, 1.0)
    return singular[..., 0] + singular[..., 1] + sign * singular[..., 2]


def rigid_residual_rms_m(source_m: np.ndarray, target_m: np.ndarray) -> np.ndarray:
    """RMS joint distance after the best rigid motion of each source onto its target, batched, without an SVD.

    With the centred points ``A``, ``B`` and ``M = A^T B`` the best rotation leaves the squared residual
    ``|A|^2 + |B|^2 - 2 (s1 + s2 + sign(det M) s3)`` (``s``: singular values of ``M``, from a closed form).

    Args:
        source_m, target_m: (..., J, 3) corresponding points, finite, metres.

    Returns:
        (...,) RMS distance after alignment, metres (the same as
        :func:`humancal.geometry.alignment.align_points` with ``with_scale=False``, then the RMS).
    """
    A = source_m - source_m.mean(-2, keepdims=True)
    B = target_m - target_m.mean(-2, keepdims=True)
    M = np.swapaxes(A, -1, -2) @ B
    sq = (A * A).sum((-1, -2)) + (B * B).sum((-1, -2)) - 2.0 * best_rotation_trace(M)
    return np.sqrt(np.maximum(sq, 0.0) / source_m.shape[-2])
