"""Radial lens models of the synthetic cameras: where OpenCV's radial polynomial stays one-to-one, its inverse on
that branch, and the per-camera draws of a rig's lenses (k1, k2, focal aspect, field of view).

The radial part of OpenCV's model maps an undistorted radius ``r`` (normalised image coordinates, ``hypot(x, y) /
z``) to ``r_d = r (1 + k1 r^2 + k2 r^4 + k3 r^6)``. Its slope ``1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6`` grows with every
coefficient, so of a box of coefficients the corner with the smallest ones folds first (at the smallest radius):
the config checks that corner only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["fold_radius", "distorted_radius", "undistorted_radius", "fits_monotonic", "LensDraws", "draw_lenses"]


def fold_radius(k1: float, k2: float = 0.0, k3: float = 0.0) -> float:
    """Largest undistorted radius (normalised image coordinates) up to which ``r (1 + k1 r^2 + k2 r^4 + k3 r^6)``
    grows with ``r``: the first zero of its slope, ``1 / sqrt(-3 k1)`` for a k1-only barrel lens, inf for a lens that
    never folds (pincushion, or a k2 that turns a barrel lens outwards again before it folds).

    Beyond it the model maps points from outside the field of view back into the image, so the detector treats such
    points as unseen.
    """
    k1, k2, k3 = float(k1), float(k2), float(k3)
    if k2 == 0.0 and k3 == 0.0:
        return float(1.0 / np.sqrt(-3.0 * k1)) if k1 < 0.0 else float("inf")
    # the slope as a polynomial in s = r^2: 1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3; its smallest positive real root
    roots = np.roots(np.trim_zeros([7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0], "f"))
    real = roots[np.abs(roots.imag) <= 1e-12 * np.maximum(1.0, np.abs(roots.real))].real
    positive = real[real > 0.0]
    return float(np.sqrt(positive.min())) if len(positive) else float("inf")


def distorted_radius(radius: np.ndarray, k1: np.ndarray, k2: np.ndarray | float = 0.0) -> np.ndarray:
    """``r (1 + k1 r^2 + k2 r^4)``: the image radius of undistorted radii (normalised image coordinates), broadcast."""
    r = np.asarray(radius, dtype=np.float64)
    return r * (1.0 + k1 * r * r + k2 * r**4)


def undistorted_radius(
    distorted_radius_: np.ndarray, k1: np.ndarray, k2: np.ndarray | float = 0.0
) -> np.ndarray:
    """Undistorted radius whose image under ``r_d = r (1 + k1 r^2 + k2 r^4)`` is ``distorted_radius_`` (normalised
    image coordinates), on the model's one-to-one branch; capped at :func:`fold_radius` where the distorted radius is
    out of its reach.

    Args:
        distorted_radius_: (N,) radii in the image plane, normalised (pixels / focal).
        k1: (N,) or scalar radial coefficients k1.
        k2: (N,) or scalar radial coefficients k2 (0: a k1-only lens).

    Returns:
        (N,) undistorted radii (the same where k1 = k2 = 0).
    """
    r_d = np.asarray(distorted_radius_, dtype=np.float64)
    a = np.broadcast_to(np.asarray(k1, dtype=np.float64), r_d.shape)
    b = np.broadcast_to(np.asarray(k2, dtype=np.float64), r_d.shape)
    r_max = np.array([fold_radius(u, w) for u, w in zip(a.reshape(-1), b.reshape(-1))]).reshape(r_d.shape)
    low, high = np.zeros_like(r_d), np.minimum(r_max, r_d * 2.0 + 1.0)
    # r (1 + k1 r^2 + k2 r^4) >= 2/3 r up to the fold of a k1-only lens, so 2 r_d + 1 brackets it; a k2 may bend the
    # curve lower before it folds: widen the bracket (up to the fold) until it holds the root
    for _ in range(60):
        short = (distorted_radius(high, a, b) < r_d) & (high < r_max)
        if not short.any():
            break
        high = np.where(short, np.minimum(2.0 * high, r_max), high)
    # bisection on the one-to-one branch [0, r_max], where the model grows from 0
    for _ in range(60):
        mid = 0.5 * (low + high)
        below = mid * (1.0 + a * mid * mid + b * mid**4) < r_d
        low, high = np.where(below, mid, low), np.where(below, high, mid)
    return np.where((a == 0.0) & (b == 0.0), r_d, 0.5 * (low + high))


def fits_monotonic(k1: float, k2: float, distorted_corner: float) -> bool:
    """Whether a lens ``(k1, k2)`` stays one-to-one over an image whose corner lies at ``distorted_corner``
    (normalised image radius): the largest image radius the model reaches before it folds lies beyond the corner."""
    fold = fold_radius(k1, k2)
    return not np.isfinite(fold) or float(distorted_radius(fold, k1, k2)) > distorted_corner


@dataclass(frozen=True)
class LensDraws:
    """Per-camera lens parameters of a rig.

    Attributes:
        k1: (V,) radial coefficients k1.
        k2: (V,) radial coefficients k2.
        aspect: (V,) focal aspect ``fy / fx``.
    """

    k1: np.ndarray
    k2: np.ndarray
    aspect: np.ndarray

    @property
    def distorted(self) -> bool:
        """Whether any camera has a lens other than an ideal pinhole."""
        return bool(np.any(self.k1 != 0.0) or np.any(self.k2 != 0.0))

    def distortion(self, v: int) -> np.ndarray:
        """(5,) OpenCV coefficients (k1, k2, p1, p2, k3) of camera ``v``."""
        return np.array([self.k1[v], self.k2[v], 0.0, 0.0, 0.0])


def draw_lenses(k1_range: tuple[float, float], k2_range: tuple[float, float],
                aspect_range: tuple[float, float], num: int, rng: np.random.Generator) -> LensDraws:
    """Each camera's k1, k2 and focal aspect, drawn uniformly from their ranges in that order; a range that is a
    single value (k1 and k2: (0, 0); aspect: (1, 1)) draws nothing, so configs without it keep their random
    stream (the draws of a k1-only rig are those of the generator before k2 and the aspect existed)."""
    k1 = rng.uniform(*k1_range, num) if k1_range != (0.0, 0.0) else np.zeros(num)
    k2 = rng.uniform(*k2_range, num) if k2_range != (0.0, 0.0) else np.zeros(num)
    aspect = rng.uniform(*aspect_range, num) if aspect_range != (1.0, 1.0) else np.ones(num)
    return LensDraws(k1, k2, aspect)
