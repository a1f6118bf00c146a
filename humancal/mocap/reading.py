"""Pieces shared by the mocap readers: file text, Euler rotations, axis and floor conventions.

Angles here are radians; the readers convert from the files' degrees on entry.
"""

from __future__ import annotations

import gzip
import zlib
from pathlib import Path

import numpy as np

from humancal.mocap.clip import MocapFormatError

__all__ = [
    "R_ZUP_FROM_YUP",
    "axis_rotmat",
    "euler_rotmat",
    "floor_height_m",
    "clip_name_and_subject",
    "read_text_lines",
]

R_ZUP_FROM_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""(3, 3) proper rotation (+90 deg about x) taking Y-up coordinates to Z-up: (x, y, z) -> (x, -z, y).

Both mocap formats are right-handed with y up; a person in rest pose faces +z with their left at +x. After this
rotation they face -y with their left still at +x, and the frame stays right-handed (det = +1), so the left side
stays on the person's left (a swap of two axes would mirror the body instead).
"""

_GZIP_MAGIC = b"\x1f\x8b"


def read_text_lines(path: str | Path) -> list[str]:
    """The lines of a text file, gzip-compressed or plain (detected from the content, not the name).

    Args:
        path: file to read.

    Returns:
        Lines without their end-of-line characters (LF or CRLF).

    Raises:
        FileNotFoundError: the file does not exist.
        MocapFormatError: the gzip stream is damaged or truncated, or the text is not UTF-8.
    """
    path = Path(path)
    raw = path.read_bytes()
    if raw[:2] == _GZIP_MAGIC:
        try:
            raw = gzip.decompress(raw)
        except (EOFError, OSError, zlib.error) as err:
            raise MocapFormatError(path, None, f"damaged or truncated gzip stream ({err})") from err
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise MocapFormatError(path, line, f"expected UTF-8 text, found byte {raw[err.start]:#04x}") from err
    return text.splitlines()


def clip_name_and_subject(path: str | Path) -> tuple[str, str]:
    """Clip name and subject from a CMU-style file name ``SS_TT.<ext>[.gz]``.

    The name is the file name without ``.gz`` and the format extension; the subject is the part of the
    name before the first underscore (the whole name when there is none).
    """
    name = Path(path).name
    if name.lower().endswith(".gz"):
        name = name[:-3]
    name = name.rsplit(".", 1)[0] if "." in name else name
    return name, name.split("_", 1)[0]


def axis_rotmat(axis: str, angles_rad: np.ndarray) -> np.ndarray:
    """Rotation matrices about one coordinate axis.

    Args:
        axis: ``"x"``, ``"y"`` or ``"z"`` (either case).
        angles_rad: (...) angles, radians, counter-clockwise looking down the axis (right-hand rule).

    Returns:
        (..., 3, 3) rotation matrices.
    """
    angles_rad = np.asarray(angles_rad, dtype=np.float64)
    a = axis.lower()
    if a not in ("x", "y", "z"):
        raise ValueError(f"axis_rotmat: axis must be 'x', 'y' or 'z', got {axis!r}")
    i = "xyz".index(a)
    j, k = (i + 1) % 3, (i + 2) % 3  # the plane the rotation turns, in right-handed order
    c, s = np.cos(angles_rad), np.sin(angles_rad)
    out = np.zeros(angles_rad.shape + (3, 3))
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    return out


def euler_rotmat(axes: str, angles_rad: np.ndarray) -> np.ndarray:
    """Intrinsic Euler rotation: ``R = R_axes[0](a_0) @ R_axes[1](a_1) @ ...``.

    Read left to right this rotates about the moving (body) axes in the order given; read right to left it
    is the same rotation about fixed axes in the reverse order. BVH channels use this product in channel
    order; the ASF/AMC rotations "applied in the order given" are this product with the order reversed.

    Args:
        axes: axis letters, e.g. ``"zxy"``; may be empty (identity) or repeat an axis.
        angles_rad: (..., len(axes)) angles in radians, one per letter.

    Returns:
        (..., 3, 3) rotation matrices.

    Raises:
        ValueError: the last dimension of ``angles_rad`` does not match ``axes``.
    """
    angles_rad = np.asarray(angles_rad, dtype=np.float64)
    if angles_rad.shape[-1:] != (len(axes),):
        raise ValueError(
            f"euler_rotmat: angles_rad must be (..., {len(axes)}) for axes {axes!r}, got {angles_rad.shape}"
        )
    if not axes:
        return np.broadcast_to(np.eye(3), angles_rad.shape[:-1] + (3, 3)).copy()
    out = axis_rotmat(axes[0], angles_rad[..., 0])
    for k in range(1, len(axes)):
        out = out @ axis_rotmat(axes[k], angles_rad[..., k])
    return out


def floor_height_m(foot_z_m: np.ndarray, percentile: float) -> float:
    """The floor height under a clip: a low percentile over frames of the lowest foot point of each frame.

    A low percentile rather than the minimum ignores a few glitched frames; rather than the median it still
    finds the floor in clips that are mostly airborne or on a raised surface (jumps, climbing).

    Args:
        foot_z_m: (F, K) heights of K foot points (ankles, toes), metres.
        percentile: in [0, 100].

    Returns:
        The floor height, metres.
    """
    return float(np.percentile(np.min(foot_z_m, axis=1), percentile))
