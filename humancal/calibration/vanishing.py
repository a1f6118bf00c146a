"""The vertical vanishing point of one view from the head-to-ankles lines of upright people.

Every upright standing person gives an image line from its head point to its ankle midpoint; in 3D these
lines are parallel (vertical), so in the image they meet at the vertical vanishing point. Following the
paper (Huang et al. 2024, III-B), RANSAC draws two lines, intersects them, and keeps the lines whose own
direction agrees with the direction from their midpoint to the candidate point within an angle
``gamma``; the best hypothesis is then refined by least squares over its inliers.

Points are homogeneous 3-vectors in *normalised image coordinates* ``(x - c) / s`` (``c`` the principal
point, ``s`` the half image diagonal), scaled to unit length, so a vanishing point at infinity (a camera
looking horizontally) is an ordinary point with third coordinate 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

__all__ = ["VanishingPoint", "fit_vertical_vanishing_point", "line_angles_deg"]


@dataclass(frozen=True)
class VanishingPoint:
    """A vertical vanishing point and its support.

    Attributes:
        point_h: (3,) unit homogeneous point in normalised image coordinates (third coordinate 0 at infinity).
        principal_point_px: (2,) the centre ``c`` of the normalisation, pixels.
        scale_px: the normalisation scale ``s`` (half image diagonal), pixels.
        inliers: (N,) which lines passed the angle test.
        angles_deg: (N,) angle between each line and the line from its midpoint to the point, degrees.
        rms_px: RMS over inliers of the endpoint displacement needed to make the line pass through the point,
            pixels.
    """

    point_h: np.ndarray
    principal_point_px: np.ndarray
    scale_px: float
    inliers: np.ndarray
    angles_deg: np.ndarray
    rms_px: float

    @property
    def point_px(self) -> np.ndarray:
        """(2,) the point in pixels (infinite coordinates when it is at infinity)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.principal_point_px + self.scale_px * self.point_h[:2] / self.point_h[2]

    @property
    def point_centered_h(self) -> np.ndarray:
        """(3,) the point as homogeneous pixel coordinates relative to the principal point, ``(x - c, y - c, 1)``
        up to scale (unit length)."""
        p = np.array([self.scale_px * self.point_h[0], self.scale_px * self.point_h[1], self.point_h[2]])
        return p / np.linalg.norm(p)


def line_angles_deg(point_h: np.ndarray, top: np.ndarray, bottom: np.ndarray) -> np.ndarray:
    """The paper's angle test: angle between each segment and the line from its midpoint to a point.

    Args:
        point_h: (..., 3) homogeneous points (normalised coordinates), broadcast against the segments.
        top, bottom: (N, 2) segment ends (normalised coordinates).

    Returns:
        (..., N) angles in degrees, in [0, 90].
    """
    mid = 0.5 * (top + bottom)
    e = top - bottom
    e = e / np.linalg.norm(e, axis=-1, keepdims=True)
    p = np.asarray(point_h)[..., None, :]
    d = p[..., :2] - p[..., 2:3] * mid  # direction midpoint -> point, valid for points at infinity too
    cross = np.abs(d[..., 0] * e[:, 1] - d[..., 1] * e[:, 0])
    dot = np.abs(d[..., 0] * e[:, 0] + d[..., 1] * e[:, 1])
    return np.degrees(np.arctan2(cross, dot))


def _intersections(lines_a: np.ndarray, lines_b: np.ndarray) -> np.ndarray:
    v = np.cross(lines_a, lines_b)
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


def _residuals_px(point_h: np.ndarray, top: np.ndarray, bottom: np.ndarray, scale_px: float) -> np.ndarray:
    """Endpoint displacement (pixels) of turning each segment about its midpoint through the point."""
    mid = 0.5 * (top + bottom)
    e = top - bottom
    half_len = 0.5 * np.linalg.norm(e, axis=1)
    e = e / (2.0 * half_len[:, None])
    d = point_h[:2] - point_h[2] * mid
    sin = (d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]) / np.maximum(np.linalg.norm(d, axis=1), 1e-12)
    return sin * half_len * scale_px


def _refine(point_h: np.ndarray, top: np.ndarray, bottom: np.ndarray, scale_px: float, soft_px: float) -> np.ndarray:
    """Least squares (soft-L1) over the unit sphere, parametrised in the tangent plane at ``point_h``."""
    u = np.linalg.svd(point_h[None])[2][1:]  # (2, 3) orthonormal tangent basis

    def point(p: np.ndarray) -> np.ndarray:
        q = point_h + p @ u
        return q / np.linalg.norm(q)

    fit = least_squares(
        lambda p: _residuals_px(point(p), top, bottom, scale_px), np.zeros(2), loss="soft_l1", f_scale=soft_px
    )
    return point(fit.x)


def fit_vertical_vanishing_point(
    head_px: np.ndarray,
    ankle_px: np.ndarray,
    principal_point_px: np.ndarray,
    scale_px: float,
    rng: np.random.Generator,
    *,
    angle_threshold_deg: float = 2.0,
    iterations: int = 1000,
    soft_px: float = 3.0,
) -> VanishingPoint:
    """RANSAC with the paper's angle test, then least squares over the inliers (repeated until stable).

    Args:
        head_px, ankle_px: (N, 2) head points and ankle midpoints of upright candidates, pixels, N >= 2.
        principal_point_px: (2,) normalisation centre, pixels.
        scale_px: normalisation scale, pixels (e.g. the half image diagonal).
        rng: source of randomness for the samples.
        angle_threshold_deg: the angle ``gamma`` above which a line is an outlier, degrees.
        iterations: number of two-line samples (all pairs when there are fewer).
        soft_px: soft-L1 scale of the refinement, pixels.

    Returns:
        The :class:`VanishingPoint`.

    Raises:
        ValueError: fewer than two lines, or non-finite input.
    """
    c = np.asarray(principal_point_px, dtype=np.float64)
    top = (np.asarray(head_px, dtype=np.float64) - c) / scale_px
    bottom = (np.asarray(ankle_px, dtype=np.float64) - c) / scale_px
    n = len(top)
    if n < 2 or top.shape != (n, 2) or bottom.shape != (n, 2):
        raise ValueError(f"need (N, 2) head and ankle points with N >= 2, got {top.shape} and {bottom.shape}")
    if not (np.isfinite(top).all() and np.isfinite(bottom).all()):
        raise ValueError("head and ankle points must be finite")
    ones = np.ones((n, 1))
    lines = np.cross(np.hstack([top, ones]), np.hstack([bottom, ones]))
    if n * (n - 1) // 2 <= iterations:
        i, j = np.triu_indices(n, 1)
    else:
        i = rng.integers(0, n, iterations)
        j = (i + rng.integers(1, n, iterations)) % n
    hypotheses = _intersections(lines[i], lines[j])
    ok = np.linalg.norm(np.cross(lines[i], lines[j]), axis=1) > 0
    hypotheses = hypotheses[ok] if ok.any() else hypotheses
    best, best_cost = None, np.inf
    for chunk in np.array_split(hypotheses, max(1, len(hypotheses) // 256)):
        angles = line_angles_deg(chunk, top, bottom)  # (H, N)
        cost = np.minimum(angles, angle_threshold_deg).sum(1)  # MSAC: truncated angles
        k = int(cost.argmin())
        if cost[k] < best_cost:
            best, best_cost = chunk[k], cost[k]
    point = best
    inliers = line_angles_deg(point, top, bottom) < angle_threshold_deg
    for _ in range(3):
        if inliers.sum() < 2:
            break
        point = _refine(point, top[inliers], bottom[inliers], scale_px, soft_px)
        new = line_angles_deg(point, top, bottom) < angle_threshold_deg
        if np.array_equal(new, inliers):
            break
        inliers = new
    angles = line_angles_deg(point, top, bottom)
    res = _residuals_px(point, top[inliers], bottom[inliers], scale_px) if inliers.any() else np.array([np.nan])
    if point[2] < 0:
        point = -point
    return VanishingPoint(point, c, float(scale_px), inliers, angles, float(np.sqrt(np.mean(res**2))))
