"""The final world frame: Z up, the floor at z = 0, from the people standing in the scene.

Until this step the world is camera 0's frame. The up direction comes from the plane through the sole points
(heels, toes) of standing people when they cover enough of the floor (its normal is then known to a fraction
of a degree), otherwise from the mean of their plumb lines (shoulders to ankles), whose individual leans
average out over people facing different ways. The floor height is the median over standing people of their
lowest sole point. Standing is judged on the reconstructed 3D keypoints themselves
(:func:`humancal.lifter.standing_score`: straight knees and hips, both feet down), which needs no camera: the
lifter's upright score also asks for the body to be upright *in the image*, which fails for steeply pitched
cameras and leaning views. The horizontal
origin is the median ground position of all people and the x axis is camera 0's viewing direction projected on
the floor. The metric scale is kept (it comes from the lifted body size).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from humancal.calibration.types import FOOT_JOINTS, CalibrationError, ankle_midpoints, plumb_points

__all__ = ["FloorAlignment", "align_to_floor"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class FloorAlignment:
    """The world change and the floor it was fitted to.

    Attributes:
        Q_new_from_old: (3, 3) rotation of old world coordinates into the new (Z up) frame.
        origin_old_m: (3,) the new origin in old world coordinates, metres: ``X_new = Q (X_old - origin)``.
        up_source: ``"floor_plane"`` or ``"plumb_lines"``.
        plane_vs_plumb_deg: angle between the two up estimates, degrees (NaN when one is missing).
        floor_points_m: (G, 3) every group's ground position (ankle midpoint dropped onto the floor), new frame.
        standing_groups: number of standing groups used.
        floor_rms_m: RMS distance of the standing people's lowest sole points from the floor, metres.
    """

    Q_new_from_old: np.ndarray
    origin_old_m: np.ndarray
    up_source: str
    plane_vs_plumb_deg: float
    floor_points_m: np.ndarray
    standing_groups: int
    floor_rms_m: float

    def apply_to_camera(self, R_cam_from_world: np.ndarray, t_cam_from_world_m: np.ndarray):
        """Extrinsics in the new frame: ``R Q^T`` and ``R origin + t``."""
        return R_cam_from_world @ self.Q_new_from_old.T, R_cam_from_world @ self.origin_old_m + t_cam_from_world_m


def _plane_normal(points: np.ndarray, iterations: int = 3) -> tuple[np.ndarray, float]:
    """Robust plane normal (unit, sign arbitrary) and the spread of the points in the plane (2nd singular value)."""
    keep = np.ones(len(points), bool)
    normal, spread = np.array([0.0, 0.0, 1.0]), 0.0
    for _ in range(iterations):
        centre = points[keep].mean(0)
        _, s, vt = np.linalg.svd(points[keep] - centre, full_matrices=False)
        normal = vt[2]
        spread = s[1] / np.sqrt(max(keep.sum(), 1))
        dist = np.abs((points - centre) @ normal)
        keep = dist < max(3.0 * 1.4826 * np.median(dist[keep]), 0.02)
    return normal, float(spread)


def align_to_floor(
    points_world_m: np.ndarray,
    upright_score: np.ndarray,
    R_cam0_from_world: np.ndarray,
    *,
    upright_threshold: float = 0.5,
    min_spread_m: float = 0.25,
    min_standing: int = 5,
) -> FloorAlignment:
    """Find the floor and the new world frame (see the module docstring).

    Args:
        points_world_m: (G, 23, 3) keypoints of the matched groups, old world frame, metres.
        upright_score: (G,) how much each group stands (e.g. :func:`humancal.lifter.standing_score` of its keypoints; NaN counts as not standing).
        R_cam0_from_world: (3, 3) camera 0's rotation in the old frame (its viewing direction sets the x axis).
        upright_threshold: groups at least this upright count as standing.
        min_spread_m: minimum in-plane spread (std) of the sole points to trust the plane normal, metres.
        min_standing: fewer standing groups than this is an error.

    Returns:
        :class:`FloorAlignment`.

    Raises:
        CalibrationError: fewer than ``min_standing`` standing people were matched across views.
    """
    X = np.asarray(points_world_m, dtype=np.float64)
    standing = np.asarray(upright_score) >= upright_threshold
    if standing.sum() < min_standing:
        raise CalibrationError(
            f"only {int(standing.sum())} standing people were matched across views (need {min_standing}): "
            "the floor cannot be found"
        )
    top, bottom = plumb_points(X[standing], None, "shoulders", "ankles")
    axes = top - bottom
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    plumb = axes.mean(0)
    plumb /= np.linalg.norm(plumb)
    soles = X[standing][:, FOOT_JOINTS]
    lowest = soles[np.arange(len(soles)), np.argmin(soles @ plumb, axis=1)]
    normal, spread = _plane_normal(lowest)
    normal = normal if normal @ plumb > 0 else -normal
    angle = float(np.degrees(np.arccos(np.clip(normal @ plumb, -1.0, 1.0))))
    if spread >= min_spread_m and angle < 15.0:
        up, source = normal, "floor_plane"
    else:
        up, source = plumb, "plumb_lines"
    heights = lowest @ up
    floor = float(np.median(heights))
    rms = float(np.sqrt(np.mean((heights - floor) ** 2)))
    ground = ankle_midpoints(X)
    ground = ground - ((ground @ up) - floor)[:, None] * up
    forward = R_cam0_from_world[2] - (R_cam0_from_world[2] @ up) * up
    if np.linalg.norm(forward) < 1e-6:  # camera 0 looks straight down: use its image x axis instead
        forward = R_cam0_from_world[0] - (R_cam0_from_world[0] @ up) * up
    x_axis = forward / np.linalg.norm(forward)
    y_axis = np.cross(up, x_axis)
    Q = np.stack([x_axis, y_axis, up])
    origin = np.median(ground, axis=0)
    origin = origin - ((origin @ up) - floor) * up
    logger.info("floor: up from %s (plane vs plumb %.2f deg), %d standing people, sole rms %.3f m", source, angle,
                int(standing.sum()), rms)
    return FloorAlignment(Q, origin, source, angle, (ground - origin) @ Q.T, int(standing.sum()), rms)
