"""Rotation matrices to Euler angles that stay continuous over time (no 360-degree jumps, no branch flips)."""

from __future__ import annotations

import numpy as np

from humancal.geometry.rotations import rotmat_to_euler_deg

__all__ = ["continuous_euler_deg"]


def _principal(rotmats: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles in ``order``, radians (at gimbal lock, angles that still reproduce the matrix)."""
    angles = np.deg2rad(rotmat_to_euler_deg(rotmats.reshape(-1, 3, 3), order.upper()))
    return angles.reshape(rotmats.shape[:-2] + (3,))


def continuous_euler_deg(rotmats: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles ``R = R_order[0](a) @ R_order[1](b) @ R_order[2](c)``, continuous along axis 0.

    Every rotation has two Euler triples in a Tait-Bryan order, ``(a, b, c)`` and ``(a + 180, 180 - b, c + 180)``,
    each defined up to multiples of 360 degrees. Frame by frame, per rotation, this picks the triple and the
    multiples closest to the previous frame's angles, so an animation curve never jumps (a turn of 720 degrees
    reads 0 .. 720, not a saw-tooth). The angles are exact: ``euler -> matrix`` gives back ``rotmats``.

    Args:
        rotmats: (T, N, 3, 3) rotation matrices, T frames of N rotations.
        order: three distinct axis letters, e.g. ``"yzx"`` (BVH channel order).

    Returns:
        (T, N, 3) angles in degrees, in ``order``.
    """
    if len(order) != 3 or len(set(order.lower())) != 3 or set(order.lower()) - set("xyz"):
        raise ValueError(f"continuous_euler_deg: order must be three distinct letters of 'xyz', got {order!r}")
    principal = _principal(np.asarray(rotmats, dtype=np.float64), order)
    alternative = principal + np.array([np.pi, 0.0, np.pi])
    alternative[..., 1] = np.pi - principal[..., 1]
    out = np.empty_like(principal)
    if principal.shape[0] == 0:
        return out
    out[0] = principal[0]
    two_pi = 2.0 * np.pi
    for t in range(1, principal.shape[0]):
        previous = out[t - 1]
        first = principal[t] + two_pi * np.round((previous - principal[t]) / two_pi)
        second = alternative[t] + two_pi * np.round((previous - alternative[t]) / two_pi)
        closer = ((second - previous) ** 2).sum(-1) < ((first - previous) ** 2).sum(-1)
        out[t] = np.where(closer[:, None], second, first)
    return np.degrees(out)
