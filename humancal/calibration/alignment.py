"""Similarity transforms between point sets and camera rigs (Umeyama's least-squares solution).

Used to compare a calibrated rig with a reference one (evaluation, plots): a self-calibrated rig is only
defined up to the choice of world frame, so it is first brought onto the reference by the similarity
(scale, rotation, translation) that best maps its camera centres onto the reference centres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.camera import Camera

__all__ = ["Similarity", "umeyama", "rig_alignment_points", "align_rig"]


@dataclass(frozen=True)
class Similarity:
    """``x -> scale * R @ x + t``.

    Attributes:
        scale: positive scale.
        R: (3, 3) rotation.
        t: (3,) translation.
    """

    scale: float
    R: np.ndarray
    t: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) transformed points."""
        return self.scale * np.asarray(points) @ self.R.T + self.t

    def apply_to_camera(self, camera: Camera) -> Camera:
        """The same camera expressed in the target frame (its image is unchanged; translation scaled)."""
        R_new = camera.R_cam_from_world @ self.R.T
        return Camera.from_center(camera.K, R_new, self.apply(camera.center_world_m), camera.width_px,
                                  camera.height_px)


def umeyama(source: np.ndarray, target: np.ndarray, with_scale: bool = True) -> Similarity:
    """Least-squares similarity mapping ``source`` onto ``target`` (Umeyama 1991).

    Args:
        source, target: (N, 3) corresponding points, N >= 3 and not collinear for a unique answer.
        with_scale: estimate the scale (else 1).

    Returns:
        The :class:`Similarity`.

    Raises:
        ValueError: shapes differ, fewer than 2 points, or non-finite values.
    """
    src = np.asarray(source, dtype=np.float64)
    dst = np.asarray(target, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 2:
        raise ValueError(f"umeyama needs two (N>=2, 3) arrays of the same shape, got {src.shape} and {dst.shape}")
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        raise ValueError("umeyama: points must be finite")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    s0, d0 = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(d0.T @ s0 / len(src))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    var_s = (s0**2).sum() / len(src)
    scale = float(np.trace(np.diag(S) @ D) / var_s) if with_scale and var_s > 0 else 1.0
    return Similarity(scale, R, mu_d - scale * R @ mu_s)


def rig_alignment_points(cameras: list[Camera], length: float) -> np.ndarray:
    """Camera centres, plus (for fewer than three cameras) a point ``length`` ahead on each optical axis.

    With two cameras the centres alone leave the rotation about their baseline free; the points on the optical
    axes fix it.
    """
    centres = np.stack([c.center_world_m for c in cameras])
    if len(cameras) >= 3:
        return centres
    ahead = np.stack([c.center_world_m + length * c.R_cam_from_world[2] for c in cameras])
    return np.concatenate([centres, ahead])


def align_rig(estimated: list[Camera], reference: list[Camera]) -> Similarity:
    """Similarity mapping the estimated rig's world onto the reference world, fitted on the camera centres.

    For two cameras, points on the optical axes at the baseline length of each rig are added (see
    :func:`rig_alignment_points`).

    Raises:
        ValueError: the rigs have different numbers of cameras.
    """
    if len(estimated) != len(reference):
        raise ValueError(f"rigs differ in size: {len(estimated)} estimated vs {len(reference)} reference cameras")
    c_est = np.stack([c.center_world_m for c in estimated])
    c_ref = np.stack([c.center_world_m for c in reference])
    base_est = float(np.linalg.norm(c_est - c_est.mean(0), axis=1).mean()) or 1.0
    base_ref = float(np.linalg.norm(c_ref - c_ref.mean(0), axis=1).mean()) or 1.0
    return umeyama(rig_alignment_points(estimated, base_est), rig_alignment_points(reference, base_ref))
