"""Checked conversions shared by the camera readers and writers (every failure is a one-line FormatError)."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from humancal.camera import Camera, CameraRig
from humancal.formats.errors import FormatError
from humancal.geometry.rotations import rotmat_to_rotvec, rotvec_to_rotmat

__all__ = [
    "ROTATION_TOLERANCE",
    "numbers",
    "rotation_matrix",
    "rotation_from_rotvec",
    "rotvec_from_rotation",
    "intrinsic_matrix",
    "size_pair",
    "distortion5",
    "make_camera",
    "camera_names",
    "sizes_by_name",
    "check_writable",
]

ROTATION_TOLERANCE = 1e-5
"""Largest |R R^T - I| entry accepted for a rotation read from a file (Shelf's 8-digit rotations reach 1.2e-6)."""

PathLike = str | Path | None


def numbers(value: object, shapes: tuple[tuple[int, ...], ...], path: PathLike, field: str, what: str) -> np.ndarray:
    """``value`` as a finite float64 array of one of ``shapes``.

    Args:
        value: a (nested) list of numbers.
        shapes: accepted shapes; the array is reshaped to the first of them with its number of values.
        path, field: where the value comes from, for the message.
        what: the expected form in words ("12 numbers (row-major 3x4 [R|t])").
    """
    if isinstance(value, (str, bytes, dict)) or value is None:
        raise FormatError(path, field, what, type(value).__name__ if value is not None else "nothing")
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):  # ragged nesting
        raise FormatError(path, field, what, value) from None
    if raw.dtype.kind not in "iuf":
        raise FormatError(path, field, what, value)
    arr = raw.astype(np.float64)
    if arr.shape not in shapes:
        size = f"{arr.size} values" if arr.ndim == 1 else f"shape {arr.shape}"
        raise FormatError(path, field, what, size)
    if not np.isfinite(arr).all():
        raise FormatError(path, field, f"finite numbers ({what})", value)
    return arr.reshape(next(s for s in shapes if int(np.prod(s)) == arr.size))


def rotation_matrix(R: np.ndarray, path: PathLike, field: str) -> np.ndarray:
    """``R`` checked to be a rotation: orthonormal within :data:`ROTATION_TOLERANCE` and det +1."""
    deviation = float(np.abs(R @ R.T - np.eye(3)).max())
    if deviation > ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        raise FormatError(
            path,
            field,
            f"a rotation matrix (orthonormal within {ROTATION_TOLERANCE:g}, det +1)",
            f"max |R R^T - I| = {deviation:.3g}, det = {np.linalg.det(R):.6g}",
        )
    return R


def rotation_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of an axis-angle (Rodrigues) vector, radians."""
    return rotvec_to_rotmat(np.asarray(rotvec, dtype=np.float64).reshape(3))


def rotvec_from_rotation(R: np.ndarray) -> np.ndarray:
    """(3,) axis-angle (Rodrigues) vector of a rotation matrix, radians."""
    return rotmat_to_rotvec(np.asarray(R, dtype=np.float64))


def intrinsic_matrix(value: object, path: PathLike, field: str, shapes=((3, 3), (9,))) -> np.ndarray:
    """A 3x3 pinhole matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0."""
    K = numbers(value, shapes, path, field, "a 3x3 intrinsic matrix (9 numbers, row-major)").reshape(3, 3)
    if not (K[0, 0] > 0 and K[1, 1] > 0 and K[1, 0] == 0 and np.array_equal(K[2], [0.0, 0.0, 1.0])):
        raise FormatError(path, field, "[[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0", K)
    return K


def size_pair(value: object, path: PathLike, field: str) -> tuple[int, int]:
    """(width_px, height_px): two positive integers (integral floats such as 1920.0 accepted)."""
    wh = numbers(value, ((2,),), path, field, "[width, height] in pixels")
    if not all(x > 0 and x == int(x) for x in wh):
        raise FormatError(path, field, "two positive integers [width, height]", wh)
    return int(wh[0]), int(wh[1])


def distortion5(value: object, path: PathLike, field: str, lengths: tuple[int, ...] = (4, 5)) -> np.ndarray:
    """OpenCV (k1, k2, p1, p2[, k3]) as 5 numbers (k3 = 0 when only 4 are given)."""
    flat_shapes = tuple(s for n in lengths for s in ((n,), (1, n), (n, 1)))
    what = f"{' or '.join(map(str, lengths))} distortion numbers (k1, k2, p1, p2, k3)"
    d = numbers(value, flat_shapes, path, field, what)
    return np.concatenate([d.reshape(-1), np.zeros(5 - d.size)])


def make_camera(
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    size: tuple[int, int],
    distortion: np.ndarray,
    path: PathLike,
    field: str,
) -> Camera:
    """A Camera after checking R (:func:`rotation_matrix`)."""
    rotation_matrix(R, path, field)
    return Camera(K, R, t, size[0], size[1], distortion)


def camera_names(names: Sequence[str] | None, count: int, *, pattern: str | None = None) -> list[str]:
    """``names`` checked (``count`` distinct strings matching ``pattern`` when given), or ``cam_00``, ``cam_01``...

    Raises:
        FormatError: wrong count, duplicates, or a name the format cannot hold.
    """
    if names is None:
        return [f"cam_{i:02d}" for i in range(count)]
    names = [str(n) for n in names]
    if len(names) != count:
        raise FormatError(None, "names", f"one name per camera ({count})", f"{len(names)} names")
    if len(set(names)) != len(names):
        raise FormatError(None, "names", "distinct camera names", names)
    if pattern is not None:
        bad = [n for n in names if not re.fullmatch(pattern, n)]
        if bad:
            raise FormatError(None, "names", f"names matching {pattern}", bad)
    return names


def sizes_by_name(
    image_size: tuple[int, int] | Sequence[tuple[int, int]] | Mapping[str, tuple[int, int]] | None,
    names: list[str],
    path: PathLike,
) -> list[tuple[int, int]]:
    """The ``image_size`` argument as one (width_px, height_px) per camera name.

    Accepts one pair for all cameras, a sequence of pairs in file order, or a mapping by camera name.
    """
    if image_size is None:
        expected = "image_size=(width_px, height_px), one pair or one per camera (not in this file)"
        raise FormatError(path, "image size", expected, "none")
    if isinstance(image_size, Mapping):
        missing = [n for n in names if n not in image_size]
        if missing:
            raise FormatError(path, "image size", f"an image_size for every camera {names}", f"none for {missing}")
        pairs = [image_size[n] for n in names]
    elif len(image_size) == 2 and all(np.isscalar(x) for x in image_size):
        pairs = [image_size] * len(names)  # type: ignore[list-item]
    else:
        if len(image_size) != len(names):
            expected = f"one (width_px, height_px) per camera ({len(names)})"
            raise FormatError(path, "image size", expected, f"{len(image_size)}")
        pairs = list(image_size)  # type: ignore[arg-type]
    return [size_pair(p, path, f"image_size of camera '{n}'") for p, n in zip(pairs, names)]


def check_writable(cameras: CameraRig, what: str) -> CameraRig:
    """The rig checked to be writable: at least one camera, all finite, rotations orthonormal, K a pinhole matrix
    (a list of cameras is checked camera by camera and returned as a rig)."""
    cameras = list(cameras)
    if not cameras:
        raise FormatError(None, "cameras", f"at least one camera to write as {what}", "none")
    for i, cam in enumerate(cameras):
        if not isinstance(cam, Camera):
            raise FormatError(None, f"cameras[{i}]", "a humancal.camera.Camera", type(cam).__name__)
        values = np.concatenate([cam.K.ravel(), cam.R_cam_from_world.ravel(), cam.t_cam_from_world_m, cam.distortion])
        if not np.isfinite(values).all():
            raise FormatError(None, f"cameras[{i}]", "finite K, R, t and distortion", "non-finite values")
        rotation_matrix(cam.R_cam_from_world, None, f"cameras[{i}].R_cam_from_world")
        intrinsic_matrix(cam.K, None, f"cameras[{i}].K")
    return CameraRig.of(cameras)
