"""Rotation conversions and distances, a thin layer over roma.

Names read source to target with the representation spelled out. Every function takes numpy arrays or torch
tensors with any leading batch shape and returns the same kind: numpy in, float64 numpy out (computed in float64
torch); a tensor in, a tensor out (differentiable, its dtype and device kept).

Representations (``docs/conventions.md``): rotation matrices ``(..., 3, 3)`` inside the library; rotation
vectors (axis times angle, radians) ``(..., 3)`` at file boundaries; the 6D form is the first two columns of the
matrix, ``(..., 3, 2)``; quaternions ``(..., 4)`` are (x, y, z, w), the order of roma, scipy and glTF (COLMAP
writes (w, x, y, z): its reader and writer reorder).

Example:
    >>> import numpy as np
    >>> from humancal.geometry.rotations import rotation_angle_deg, rotmat_to_rotvec, rotvec_to_rotmat
    >>> R = rotvec_to_rotmat(np.array([0.0, 0.0, np.pi / 2]))  # a quarter turn about z
    >>> (R @ [1.0, 0.0, 0.0]).round(6).tolist()
    [0.0, 1.0, 0.0]
    >>> float(rotation_angle_deg(R).round(6)), rotmat_to_rotvec(R).round(6).tolist()
    (90.0, [0.0, 0.0, 1.570796])
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np
import roma
import torch

__all__ = [
    "rotvec_to_rotmat",
    "rotmat_to_rotvec",
    "axis_angle_to_rotmat",
    "rotmat_to_6d",
    "sixd_to_rotmat",
    "project_to_rotmat",
    "rotation_angle_deg",
    "rotation_distance_deg",
    "rotmat_a_to_b",
    "rotmat_to_quat_xyzw",
    "quat_xyzw_to_rotmat",
    "rotmat_to_euler_deg",
    "angle_between_deg",
]

Array = TypeVar("Array", np.ndarray, torch.Tensor)


def _torch_op(fn: Callable[..., torch.Tensor], *args) -> np.ndarray | torch.Tensor:
    """Run a tensor function on numpy (float64, returned as numpy) or tensor arguments (returned as tensors)."""
    if any(isinstance(a, torch.Tensor) for a in args):
        return fn(*(torch.as_tensor(a) if not isinstance(a, torch.Tensor) else a for a in args))
    tensors = [torch.as_tensor(np.asarray(a, dtype=np.float64)) for a in args]
    return fn(*tensors).numpy()


def _check_last(x, shape: tuple[int, ...], name: str) -> None:
    if tuple(x.shape[len(x.shape) - len(shape):]) != shape or len(x.shape) < len(shape):
        raise ValueError(f"{name} must have shape (..., {', '.join(map(str, shape))}), got {tuple(x.shape)}")


def rotvec_to_rotmat(rotvec: Array) -> Array:
    """Rotation vectors (axis times angle, radians) to matrices (Rodrigues).

    Args:
        rotvec: (..., 3) rotation vectors, radians.

    Returns:
        (..., 3, 3) rotation matrices.

    Raises:
        ValueError: wrong shape.
    """
    _check_last(rotvec, (3,), "rotvec")
    return _torch_op(roma.rotvec_to_rotmat, rotvec)


def rotmat_to_rotvec(R: Array) -> Array:
    """Rotation matrices to rotation vectors (axis times angle, angle in [0, pi], radians).

    Args:
        R: (..., 3, 3) rotation matrices.

    Returns:
        (..., 3) rotation vectors, radians.

    Raises:
        ValueError: wrong shape.
    """
    _check_last(R, (3, 3), "R")
    return _torch_op(roma.rotmat_to_rotvec, R)


def axis_angle_to_rotmat(axis: Array, angle_rad: Array) -> Array:
    """Rotations about unit axes by angles (right-handed), broadcast against each other.

    Args:
        axis: (..., 3) unit axes.
        angle_rad: (...) angles, radians.

    Returns:
        (..., 3, 3) rotation matrices.

    Raises:
        ValueError: wrong shape of ``axis``.
    """
    _check_last(axis, (3,), "axis")
    return _torch_op(lambda a, t: roma.rotvec_to_rotmat(a * t[..., None]), axis, angle_rad)


def rotmat_to_6d(R: Array) -> Array:
    """The 6D form of rotations: their first two columns, (..., 3, 2)."""
    _check_last(R, (3, 3), "R")
    return R[..., :2]


def sixd_to_rotmat(sixd: Array) -> Array:
    """Rotation matrices from 6D forms (Gram-Schmidt on the two columns; any full-rank input is accepted).

    Args:
        sixd: (..., 3, 2) two 3D columns.

    Returns:
        (..., 3, 3) rotation matrices whose first column is the normalised first input column.
    """
    _check_last(sixd, (3, 2), "sixd")
    return _torch_op(_gram_schmidt_columns_contiguous, sixd)


def _gram_schmidt_columns_contiguous(sixd: torch.Tensor) -> torch.Tensor:
    """``roma.special_gramschmidt`` on a copy whose columns are contiguous in memory.

    roma reads the two columns as strided views of a row-major (..., 3, 2) tensor; torch's norm over such a view
    takes a slow path (on 3,600 person-frames x 21 bones, the body fit's batch, the forward and backward passes
    took 31 ms instead of 17 ms at 2 threads). The values are the same; only the layout changes.
    """
    return roma.special_gramschmidt(sixd.transpose(-1, -2).contiguous().transpose(-1, -2))


def project_to_rotmat(M: Array) -> Array:
    """The rotation nearest to each matrix in the Frobenius norm (special orthogonal Procrustes).

    Args:
        M: (..., 3, 3) matrices (e.g. a weighted sum of outer products of corresponding vectors).

    Returns:
        (..., 3, 3) rotation matrices (det +1).
    """
    _check_last(M, (3, 3), "M")
    return _torch_op(roma.special_procrustes, M)


def rotation_angle_deg(R: Array) -> Array:
    """Angle of rotations, degrees in [0, 180].

    Args:
        R: (..., 3, 3) rotation matrices.

    Returns:
        (...) angles, degrees.
    """
    _check_last(R, (3, 3), "R")
    return _torch_op(lambda r: torch.rad2deg(roma.rotmat_geodesic_distance(r, torch.eye(3, dtype=r.dtype,
                                                                                            device=r.device))), R)


def rotation_distance_deg(R_a: Array, R_b: Array) -> Array:
    """Geodesic angle between rotations (the angle of ``R_a @ R_b.T``), degrees in [0, 180].

    Args:
        R_a, R_b: (..., 3, 3) rotation matrices (broadcast).

    Returns:
        (...) angles, degrees.
    """
    _check_last(R_a, (3, 3), "R_a")
    _check_last(R_b, (3, 3), "R_b")
    return _torch_op(lambda a, b: torch.rad2deg(roma.rotmat_geodesic_distance(*torch.broadcast_tensors(a, b))),
                     R_a, R_b)


def _a_to_b(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    a = a / torch.linalg.norm(a, dim=-1, keepdim=True)
    b = b / torch.linalg.norm(b, dim=-1, keepdim=True)
    a, b = torch.broadcast_tensors(a, b)
    # the unit quaternion (xyzw) of the rotation by the angle between a and b about a x b, before normalising:
    # (a x b, 1 + a . b), half the angle by construction; singular only for opposite vectors
    q = torch.cat([torch.linalg.cross(a, b), 1.0 + (a * b).sum(-1, keepdim=True)], dim=-1)
    return roma.unitquat_to_rotmat(q / torch.linalg.norm(q, dim=-1, keepdim=True))


def rotmat_a_to_b(a: Array, b: Array) -> Array:
    """The smallest rotation taking direction ``a`` onto direction ``b`` (about the axis ``a x b``).

    Args:
        a, b: (..., 3) directions (normalised here; broadcast). Opposite directions have no unique answer
            (NaN rows).

    Returns:
        (..., 3, 3) rotations ``R`` with ``R @ a / |a| = b / |b|``.
    """
    _check_last(a, (3,), "a")
    _check_last(b, (3,), "b")
    return _torch_op(_a_to_b, a, b)


def rotmat_to_quat_xyzw(R: Array) -> Array:
    """Unit quaternions of rotations, (x, y, z, w). ``q`` and ``-q`` are the same rotation: either may come out.

    Args:
        R: (..., 3, 3) rotation matrices.

    Returns:
        (..., 4) unit quaternions (x, y, z, w).
    """
    _check_last(R, (3, 3), "R")
    return _torch_op(roma.rotmat_to_unitquat, R)


def quat_xyzw_to_rotmat(q: Array) -> Array:
    """Rotation matrices of quaternions (x, y, z, w), normalised first.

    Args:
        q: (..., 4) quaternions (x, y, z, w), not zero.

    Returns:
        (..., 3, 3) rotation matrices.
    """
    _check_last(q, (4,), "q")
    return _torch_op(lambda x: roma.unitquat_to_rotmat(roma.quat_normalize(x)), q)


def rotmat_to_euler_deg(R: Array, order: str) -> Array:
    """Euler angles of rotations, degrees.

    Args:
        R: (..., 3, 3) rotation matrices.
        order: three axis letters, upper case for intrinsic rotations (``"YZX"``: ``R = R_y(a) @ R_z(b) @ R_x(c)``),
            lower case for extrinsic ones. At gimbal lock the third angle is 0 (the angles still give ``R``).

    Returns:
        (..., 3) angles in ``order``, degrees: the first and third in (-180, 180], the middle one in [-90, 90]
        (Tait-Bryan orders) or [0, 180] (proper Euler orders).
    """
    _check_last(R, (3, 3), "R")
    return _torch_op(lambda r: roma.rotmat_to_euler(order, r, degrees=True), R)


def angle_between_deg(a: Array, b: Array) -> Array:
    """Angle between directions, degrees in [0, 180] (robust near 0 and 180: ``atan2(|a x b|, a . b)``).

    Args:
        a, b: (..., 3) directions (any length but zero; broadcast).

    Returns:
        (...) angles, degrees.

    Example:
        >>> import numpy as np
        >>> float(angle_between_deg(np.array([1.0, 0.0, 0.0]), np.array([1.0, 1.0, 0.0])).round(6))
        45.0
    """
    _check_last(a, (3,), "a")
    _check_last(b, (3,), "b")

    def angle(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        u, v = torch.broadcast_tensors(u, v)
        return torch.rad2deg(torch.atan2(torch.linalg.norm(torch.linalg.cross(u, v), dim=-1), (u * v).sum(-1)))

    return _torch_op(angle, a, b)
