"""How much each joint is hidden in each view, from a capsule model of the bodies.

Each body is approximated by capsules (segments with a radius) along its limbs, trunk and head. A joint is
occluded in a view when its projection falls inside the projected capsule of a body part that lies in front
of it: another person's, or its own trunk and head (self-occlusion, e.g. the far shoulder seen from the
side). The degree is soft: 1 when the joint projects well inside the capsule, falling to 0 just outside.
"""

from __future__ import annotations

import numpy as np

from humancal.keypoints import JOINT_INDEX, NUM_JOINTS

__all__ = ["CAPSULES", "occlusion_degree"]

_J = JOINT_INDEX
# Extra points appended after the 23 keypoints: neck (shoulder midpoint), pelvis (hip midpoint), head centre
# (ear midpoint: the face is in front of it, so it is hidden when seen from behind).
_NECK, _PELVIS, _HEAD = NUM_JOINTS, NUM_JOINTS + 1, NUM_JOINTS + 2

CAPSULES: tuple[tuple[int, int, float, bool], ...] = (
    (_HEAD, _HEAD, 0.11, True),
    (_NECK, _PELVIS, 0.15, True),
    (_J["left_shoulder"], _J["left_hip"], 0.07, True),
    (_J["right_shoulder"], _J["right_hip"], 0.07, True),
    (_J["left_shoulder"], _J["left_elbow"], 0.05, False),
    (_J["right_shoulder"], _J["right_elbow"], 0.05, False),
    (_J["left_elbow"], _J["left_wrist"], 0.04, False),
    (_J["right_elbow"], _J["right_wrist"], 0.04, False),
    (_J["left_hip"], _J["left_knee"], 0.08, False),
    (_J["right_hip"], _J["right_knee"], 0.08, False),
    (_J["left_knee"], _J["left_ankle"], 0.055, False),
    (_J["right_knee"], _J["right_ankle"], 0.055, False),
    (_J["left_heel"], _J["left_big_toe"], 0.04, False),
    (_J["right_heel"], _J["right_big_toe"], 0.04, False),
)
"""(point a, point b, radius in metres, occludes its own body) for every capsule; points index the 23 keypoints
followed by neck, pelvis and head centre."""

_CAP_A = np.array([c[0] for c in CAPSULES])
_CAP_B = np.array([c[1] for c in CAPSULES])
_CAP_RADIUS_M = np.array([c[2] for c in CAPSULES])
_CAP_SELF = np.array([c[3] for c in CAPSULES])
_DEPTH_MARGIN_M = 0.06
"""A capsule hides a joint only if its axis is this much closer to the camera (its surface is in front)."""


def _with_extra_points(points: np.ndarray) -> np.ndarray:
    """Append neck, pelvis and head centre to (..., 23, D) points."""
    neck = points[..., [_J["left_shoulder"], _J["right_shoulder"]], :].mean(axis=-2)
    pelvis = points[..., [_J["left_hip"], _J["right_hip"]], :].mean(axis=-2)
    head = points[..., [_J["left_ear"], _J["right_ear"]], :].mean(axis=-2)
    return np.concatenate([points, neck[..., None, :], pelvis[..., None, :], head[..., None, :]], axis=-2)


def _capsule_occlusion(
    joints_px: np.ndarray,
    joint_depth_m: np.ndarray,
    a_px: np.ndarray,
    b_px: np.ndarray,
    a_depth_m: np.ndarray,
    b_depth_m: np.ndarray,
    radius_m: np.ndarray,
    focal_px: float,
) -> np.ndarray:
    """Occlusion of N x J joints by N x C capsules (one occluding body per row).

    Args:
        joints_px: (N, J, 2); joint_depth_m: (N, J).
        a_px, b_px: (N, C, 2) capsule ends; a_depth_m, b_depth_m: (N, C); radius_m: (C,).
        focal_px: focal length, pixels.

    Returns:
        (N, J) the largest occlusion degree over the capsules.
    """
    # Components kept apart: plain elementwise arithmetic on (N, J, C) arrays is much cheaper than
    # reductions over a trailing axis of length 2.
    ab_x, ab_y = (b_px[..., 0] - a_px[..., 0])[:, None], (b_px[..., 1] - a_px[..., 1])[:, None]  # (N, 1, C)
    ap_x = joints_px[..., 0][:, :, None] - a_px[..., 0][:, None]  # (N, J, C)
    ap_y = joints_px[..., 1][:, :, None] - a_px[..., 1][:, None]
    length2 = np.maximum(ab_x * ab_x + ab_y * ab_y, 1e-9)
    s = np.clip((ap_x * ab_x + ap_y * ab_y) / length2, 0.0, 1.0)
    dx, dy = ap_x - s * ab_x, ap_y - s * ab_y
    dist = np.sqrt(dx * dx + dy * dy)
    capsule_depth = a_depth_m[:, None] + s * (b_depth_m - a_depth_m)[:, None]
    radius_px = focal_px * radius_m / np.maximum(capsule_depth, 1e-3)
    in_front = (capsule_depth > 0.0) & (capsule_depth < joint_depth_m[..., None] - _DEPTH_MARGIN_M)
    with np.errstate(invalid="ignore"):
        degree = np.clip((1.25 * radius_px - dist) / (0.5 * radius_px), 0.0, 1.0)
    degree = np.where(in_front, np.nan_to_num(degree, nan=0.0), 0.0)
    return degree.max(axis=-1)


def occlusion_degree(pixels_px: np.ndarray, depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """Occlusion of every joint of every person in one view.

    Only joints inside the image box of another person who is nearer somewhere are compared with that
    person's capsules, so the cost grows with the number of actual overlaps, not with P^2.

    Args:
        pixels_px: (P, F, 23, 2) projections of the joints, pixels (NaN behind the camera).
        depth_m: (P, F, 23) depth of the joints along the optical axis, metres.
        focal_px: the view's focal length (converts capsule radii to pixels), pixels.

    Returns:
        (P, F, 23) occlusion degree in [0, 1] (0: nothing in front; 1: well inside a closer body part).
    """
    num_people, num_frames = pixels_px.shape[:2]
    points = _with_extra_points(pixels_px)
    depths = _with_extra_points(depth_m[..., None])[..., 0]
    a, b = points[:, :, _CAP_A], points[:, :, _CAP_B]  # (P, F, C, 2)
    za, zb = depths[:, :, _CAP_A], depths[:, :, _CAP_B]  # (P, F, C)

    # Self-occlusion by one's own trunk and head.
    flat = num_people * num_frames
    own = _capsule_occlusion(
        pixels_px.reshape(flat, NUM_JOINTS, 2),
        depth_m.reshape(flat, NUM_JOINTS),
        a[:, :, _CAP_SELF].reshape(flat, -1, 2),
        b[:, :, _CAP_SELF].reshape(flat, -1, 2),
        za[:, :, _CAP_SELF].reshape(flat, -1),
        zb[:, :, _CAP_SELF].reshape(flat, -1),
        _CAP_RADIUS_M[_CAP_SELF],
        focal_px,
    )
    out = own.reshape(num_people, num_frames, NUM_JOINTS)
    if num_people == 1:
        return out

    # Candidate (target p, occluder q, frame) triples: boxes overlap and q is nearer than p's farthest joint.
    # Points behind the camera (NaN) take no part in boxes and depth ranges.
    seen = np.isfinite(points).all(axis=-1)
    nearest = np.where(seen, depths, np.inf).min(axis=-1)  # (P, F)
    farthest = np.where(seen[..., :NUM_JOINTS], depth_m, -np.inf).max(axis=-1)
    pad = focal_px * _CAP_RADIUS_M.max() / np.maximum(nearest, 1e-3)
    lo = np.where(seen[..., None], points, np.inf).min(axis=-2) - pad[..., None]
    hi = np.where(seen[..., None], points, -np.inf).max(axis=-2) + pad[..., None]
    with np.errstate(invalid="ignore"):
        overlap = np.all((lo[:, None] <= hi[None, :]) & (lo[None, :] <= hi[:, None]), axis=-1)  # (P, Q, F)
    nearer = nearest[None, :] < farthest[:, None] - _DEPTH_MARGIN_M
    candidates = overlap & nearer & ~np.eye(num_people, dtype=bool)[:, :, None]
    p_idx, q_idx, f_idx = np.nonzero(candidates)
    # Within those, only the joints inside the occluder's box and behind its nearest point.
    joints = pixels_px[p_idx, f_idx]  # (N, J, 2)
    with np.errstate(invalid="ignore"):
        inside = np.all((joints >= lo[q_idx, f_idx][:, None]) & (joints <= hi[q_idx, f_idx][:, None]), axis=-1)
    inside &= depth_m[p_idx, f_idx] > nearest[q_idx, f_idx][:, None] + _DEPTH_MARGIN_M
    row, joint = np.nonzero(inside)
    if row.size == 0:
        return out
    pair_p, pair_q, pair_f = p_idx[row], q_idx[row], f_idx[row]
    degree = _capsule_occlusion(
        pixels_px[pair_p, pair_f, joint][:, None],
        depth_m[pair_p, pair_f, joint][:, None],
        a[pair_q, pair_f],
        b[pair_q, pair_f],
        za[pair_q, pair_f],
        zb[pair_q, pair_f],
        _CAP_RADIUS_M,
        focal_px,
    )[:, 0]
    flat_out = out.reshape(-1)
    np.maximum.at(flat_out, (pair_p * num_frames + pair_f) * NUM_JOINTS + joint, degree)
    return flat_out.reshape(num_people, num_frames, NUM_JOINTS)
