"""The final world frame: Z up, the floor at z = 0, from whatever the people in the scene give.

Until this step the world is camera 0's frame. Which people are standing is judged on the reconstructed 3D
keypoints themselves (:func:`humancal.lifter.standing_score`: straight knees and hips, both feet down), which
needs no camera.

With enough standing people (``min_standing``) the up direction comes from the plane through their sole points
(heels, toes) when they cover enough of the floor (its normal is then known to a fraction of a degree),
otherwise from the mean of their plumb lines (shoulders to ankles), whose individual leans average out over
people facing different ways; the floor height is the median over them of their lowest sole point.

Without them (people who sit, crouch, bend) the cues are the ones every pose gives:

* **torso axes**: the direction from the hips to the shoulders, averaged over all people and frames. A seated
  or crouching trunk leans, but the leans of people facing different ways average out; it is a coarse up
  direction (its uncertainty, the angular spread over the square root of the count, is reported);
* **foot contacts**: the lowest sole point of every person (along that coarse up direction) lies on the floor
  for anyone whose feet touch the ground, standing or not; a robust plane through them gives the up direction
  and the floor height when the points cover enough of the floor and the plane agrees with the torso axes.

When neither works (too few people, torso axes pointing every way, contacts that fit no plane near the torso
direction), :class:`NoFloorError` says why and the caller keeps camera 0's frame. The horizontal origin is the
median ground position of all people and the x axis is camera 0's viewing direction projected on the floor.
The metric scale is kept (it comes from the lifted body size, i.e. from body proportions, standing or not).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from humancal.calibration.types import FOOT_JOINTS, CalibrationError, ankle_midpoints, plumb_points
from humancal.geometry.rotations import angle_between_deg
from humancal.keypoints import JOINT_INDEX

__all__ = ["FloorAlignment", "NoFloorError", "UP_SOURCES", "align_to_floor"]

logger = logging.getLogger(__name__)

UP_SOURCES: tuple[str, ...] = ("floor_plane", "plumb_lines", "contact_plane", "torso_axes")
"""Where the up direction came from: the standing people's sole plane or plumb lines, or (without enough
standing people) every person's foot contacts or torso axes."""

_TOP = (JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"])
_HIP = (JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"])


class NoFloorError(CalibrationError):
    """The people give no usable up direction or floor; the message says why (the cameras are still valid in
    camera 0's frame)."""


@dataclass(frozen=True)
class FloorAlignment:
    """The world change and the floor it was fitted to.

    Attributes:
        Q_new_from_old: (3, 3) rotation of old world coordinates into the new (Z up) frame.
        origin_old_m: (3,) the new origin in old world coordinates, metres: ``X_new = Q (X_old - origin)``.
        up_source: one of :data:`UP_SOURCES`.
        plane_vs_plumb_deg: angle between the plane normal and the coarse up direction (plumb lines of the
            standing people, or the torso axes), degrees (NaN when one is missing).
        floor_points_m: (G, 3) every group's ground position (ankle midpoint dropped onto the floor), new frame.
        standing_groups: number of standing groups.
        floor_rms_m: RMS distance of the contact points used (standing people's lowest sole points, or every
            inlying person's lowest sole point) from the floor, metres.
        up_std_deg: uncertainty (one std) of the up direction, degrees: from the plane fit's residuals and the
            contacts' spread, or the torso axes' angular spread over the square root of their count.
        contact_groups: number of groups whose lowest sole point fixed the floor height.
    """

    Q_new_from_old: np.ndarray
    origin_old_m: np.ndarray
    up_source: str
    plane_vs_plumb_deg: float
    floor_points_m: np.ndarray
    standing_groups: int
    floor_rms_m: float
    up_std_deg: float = float("nan")
    contact_groups: int = 0

    def apply_to_camera(self, R_cam_from_world: np.ndarray, t_cam_from_world_m: np.ndarray):
        """Extrinsics in the new frame: ``R Q^T`` and ``R origin + t``."""
        return R_cam_from_world @ self.Q_new_from_old.T, R_cam_from_world @ self.origin_old_m + t_cam_from_world_m


def _plane_fit(points: np.ndarray, iterations: int = 3) -> tuple[np.ndarray, float, np.ndarray, float]:
    """Robust plane: normal (unit, sign arbitrary), in-plane spread (2nd singular value per point, metres),
    inlier mask, and the inliers' RMS distance from the plane (metres)."""
    keep = np.ones(len(points), bool)
    normal, spread, rms = np.array([0.0, 0.0, 1.0]), 0.0, float("nan")
    for _ in range(iterations):
        centre = points[keep].mean(0)
        _, s, vt = np.linalg.svd(points[keep] - centre, full_matrices=False)
        normal = vt[2]
        spread = s[1] / np.sqrt(max(keep.sum(), 1))
        dist = np.abs((points - centre) @ normal)
        rms = float(np.sqrt(np.mean(dist[keep] ** 2)))
        keep = dist < max(3.0 * 1.4826 * np.median(dist[keep]), 0.02)
    return normal, float(spread), keep, rms


def _lowest_soles(X: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(G, 3) each pose's sole point lowest along ``up``."""
    soles = X[:, FOOT_JOINTS]
    return soles[np.arange(len(soles)), np.argmin(soles @ up, axis=1)]


def _torso_up(X: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Mean torso direction (hips to shoulders) of all poses: unit vector, its uncertainty (degrees) and the
    mean resultant length of the unit axes (1: all parallel, 0: pointing every way)."""
    axes = X[:, list(_TOP)].mean(1) - X[:, list(_HIP)].mean(1)
    axes = axes[np.isfinite(axes).all(1)]
    axes = axes / np.maximum(np.linalg.norm(axes, axis=1, keepdims=True), 1e-12)
    if not len(axes):
        return np.full(3, np.nan), float("nan"), 0.0
    mean = axes.mean(0)
    length = float(np.linalg.norm(mean))
    up = mean / max(length, 1e-12)
    spread = angle_between_deg(axes, up)
    return up, float(np.sqrt(np.mean(spread**2)) / np.sqrt(len(axes))), length


def _frame(X, up, floor, R_cam0_from_world):
    """The new frame's rotation and origin (old frame), and every group's ground point in the new frame."""
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
    return Q, origin, (ground - origin) @ Q.T


def align_to_floor(
    points_world_m: np.ndarray,
    upright_score: np.ndarray,
    R_cam0_from_world: np.ndarray,
    *,
    upright_threshold: float = 0.5,
    min_spread_m: float = 0.25,
    min_standing: int = 5,
    min_people: int = 3,
    max_torso_plane_deg: float = 30.0,
    min_torso_agreement: float = 0.7,
    min_coarse_agreement: float = 0.3,
) -> FloorAlignment:
    """Find the floor and the new world frame (see the module docstring).

    Args:
        points_world_m: (G, 23, 3) keypoints of the matched groups, old world frame, metres.
        upright_score: (G,) how much each group stands (e.g. :func:`humancal.lifter.standing_score` of its
            keypoints; NaN counts as not standing).
        R_cam0_from_world: (3, 3) camera 0's rotation in the old frame (its viewing direction sets the x axis).
        upright_threshold: groups at least this upright count as standing.
        min_spread_m: minimum in-plane spread (std) of the contact points to trust a plane normal, metres.
        min_standing: with at least this many standing groups the floor comes from them alone.
        min_people: fewer groups than this give no floor.
        max_torso_plane_deg: a foot-contact plane whose normal is further from the torso axes is not the floor.
        min_torso_agreement: the torso axes alone give the up direction only with at least this mean resultant
            length (1: all parallel).
        min_coarse_agreement: below this the torso axes point every way and cannot even orient the contact
            plane: no up direction.

    Returns:
        :class:`FloorAlignment`.

    Raises:
        NoFloorError: neither the standing people nor the other cues give an up direction and a floor.
    """
    X = np.asarray(points_world_m, dtype=np.float64)
    standing = np.asarray(upright_score) >= upright_threshold
    if standing.sum() >= min_standing:
        return _from_standing(X, standing, R_cam0_from_world, min_spread_m)
    if len(X) < min_people:
        raise NoFloorError(f"only {len(X)} people were matched across views (need {min_people}): no floor")
    torso, torso_std, agreement = _torso_up(X)
    refusal = (f"the people's torso axes point every way (mean resultant length {agreement:.2f}, need "
               f"{min_torso_agreement}) and only {int(standing.sum())} stand")
    if not agreement >= min_coarse_agreement:
        raise NoFloorError(f"{refusal}: no up direction")
    # the torso axes only pick each person's lowest sole point and the plane normal's sign here: bending people
    # spread them (a lower resultant length) without spoiling the contact plane
    normal, spread, inliers, rms = _plane_fit(_lowest_soles(X, torso))
    normal = normal if normal @ torso > 0 else -normal
    angle = float(angle_between_deg(normal, torso))
    if spread >= min_spread_m and angle <= max_torso_plane_deg and inliers.sum() >= min_people:
        lowest = _lowest_soles(X, normal)[inliers]
        up, source = normal, "contact_plane"
        up_std = float(np.degrees(rms / (spread * np.sqrt(inliers.sum()))))
    elif agreement >= min_torso_agreement:
        lowest = _lowest_soles(X, torso)
        up, source, up_std = torso, "torso_axes", torso_std
    else:
        raise NoFloorError(f"{refusal}, and their foot contacts fit no floor plane (in-plane spread {spread:.2f} m, "
                           f"{angle:.0f} deg from the torso axes): no up direction")
    heights = lowest @ up
    floor = float(np.median(heights))
    keep = np.abs(heights - floor) <= max(3.0 * 1.4826 * np.median(np.abs(heights - floor)), 0.02)
    floor = float(np.median(heights[keep]))
    floor_rms = float(np.sqrt(np.mean((heights[keep] - floor) ** 2)))
    Q, origin, ground = _frame(X, up, floor, R_cam0_from_world)
    logger.info("floor: up from %s (+- %.2f deg; contact plane vs torso axes %.1f deg), %d of %d people on it, "
                "%d standing, contact rms %.3f m", source, up_std, angle, int(keep.sum()), len(X),
                int(standing.sum()), floor_rms)
    return FloorAlignment(Q, origin, source, angle, ground, int(standing.sum()), floor_rms, up_std, int(keep.sum()))


def _from_standing(X, standing, R_cam0_from_world, min_spread_m) -> FloorAlignment:
    """The floor from the standing people alone: their sole plane (or plumb lines) and lowest sole points."""
    top, bottom = plumb_points(X[standing], None, "shoulders", "ankles")
    axes = top - bottom
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    plumb = axes.mean(0)
    plumb /= np.linalg.norm(plumb)
    lowest = _lowest_soles(X[standing], plumb)
    normal, spread, _, plane_rms = _plane_fit(lowest)
    normal = normal if normal @ plumb > 0 else -normal
    angle = float(angle_between_deg(normal, plumb))
    if spread >= min_spread_m and angle < 15.0:
        up, source = normal, "floor_plane"
        up_std = float(np.degrees(plane_rms / (spread * np.sqrt(len(lowest)))))
    else:
        up, source = plumb, "plumb_lines"
        spread_deg = angle_between_deg(axes, plumb)
        up_std = float(np.sqrt(np.mean(spread_deg**2)) / np.sqrt(len(axes)))
    heights = lowest @ up
    floor = float(np.median(heights))
    rms = float(np.sqrt(np.mean((heights - floor) ** 2)))
    Q, origin, ground = _frame(X, up, floor, R_cam0_from_world)
    logger.info("floor: up from %s (plane vs plumb %.2f deg), %d standing people, sole rms %.3f m", source, angle,
                int(standing.sum()), rms)
    return FloorAlignment(Q, origin, source, angle, ground, int(standing.sum()), rms, up_std, int(standing.sum()))
