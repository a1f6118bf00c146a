"""OpenCV YAML camera files as EasyMocap writes them: ``intri.yml`` and ``extri.yml`` in one folder.

``intri.yml``::

    %YAML:1.0
    ---
    names:
       - "01"
    K_01: !!opencv-matrix          # 3x3 intrinsic matrix, pixels
       rows: 3
       cols: 3
       dt: d
       data: [ fx, 0., cx, 0., fy, cy, 0., 0., 1. ]
    dist_01: !!opencv-matrix       # 1x5 (k1, k2, p1, p2, k3); 1x4 also read
       ...

``extri.yml``: the same ``names``, and per camera ``R_<name>`` (3x1 Rodrigues vector), ``Rot_<name>`` (3x3 matrix,
optional for reading) and ``T_<name>`` (3x1), world -> camera (``x_cam = R x_world + T``), metres in EasyMocap's
own calibration (its board size is given in metres). Neither file holds the image size: readers take it as an
argument. Files are read with OpenCV's ``cv2.FileStorage`` and written by hand in the layout above (the
``%YAML:1.0`` header that OpenCV 3/4, hence EasyMocap, reads and writes).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np

from humancal.camera import CameraRig
from humancal.formats._io import atomic_write_texts, read_text
from humancal.formats.cameras._checks import (
    camera_names,
    check_writable,
    distortion5,
    intrinsic_matrix,
    make_camera,
    numbers,
    rotation_from_rotvec,
    rotation_matrix,
    rotvec_from_rotation,
    sizes_by_name,
)
from humancal.formats.errors import FormatError

__all__ = ["read_easymocap", "write_easymocap", "easymocap_paths"]

INTRI_NAME = "intri.yml"
EXTRI_NAME = "extri.yml"
NAME_PATTERN = r"[A-Za-z0-9_-]+"
"""Camera names the writer accepts (they become parts of YAML keys such as ``K_<name>``)."""

_RODRIGUES_AGREEMENT = 1e-6
"""Largest entry difference accepted between ``Rot_<name>`` and the rotation of ``R_<name>``."""


def easymocap_paths(path: str | Path) -> tuple[Path, Path]:
    """(intri.yml, extri.yml) of a folder, or of one of the two files (the other is its sibling)."""
    path = Path(path)
    folder = path.parent if path.name in (INTRI_NAME, EXTRI_NAME) else path
    return folder / INTRI_NAME, folder / EXTRI_NAME


def read_easymocap(
    path: str | Path,
    *,
    image_size: tuple[int, int] | Sequence[tuple[int, int]] | Mapping[str, tuple[int, int]] | None = None,
    length_unit_m: float = 1.0,
) -> tuple[CameraRig, list[str]]:
    """Read EasyMocap's ``intri.yml`` + ``extri.yml``.

    Args:
        path: the folder holding both files, or either file.
        image_size: (width_px, height_px) for all cameras, one pair per camera in ``names`` order, or a mapping by
            camera name. Required: the files do not hold it.
        length_unit_m: metres per unit of ``T_<name>`` (1 for EasyMocap).

    Returns:
        cameras: the rig, views in the order of ``names`` in ``intri.yml``.
        names: the camera names.

    Raises:
        FileNotFoundError: a file is missing.
        FormatError: unparsable YAML; no ``names`` list; a missing or malformed matrix; ``R_`` and ``Rot_`` that
            disagree; a non-orthonormal rotation; no image size.
    """
    intri_path, extri_path = easymocap_paths(path)
    if not (np.isfinite(length_unit_m) and length_unit_m > 0):
        raise ValueError(f"length_unit_m: expected a positive number of metres per file unit, got {length_unit_m!r}")
    intri, extri = _open(intri_path), _open(extri_path)
    names = _names(intri, intri_path)
    extri_names = _names(extri, extri_path)
    if set(names) - set(extri_names):
        raise FormatError(extri_path, "names", f"every camera of {INTRI_NAME} {names}", f"{extri_names}")
    sizes = sizes_by_name(image_size, names, intri_path)
    cameras = []
    for name, size in zip(names, sizes):
        K = intrinsic_matrix(_matrix(intri, f"K_{name}", intri_path), intri_path, f"K_{name}")
        dist = distortion5(_matrix(intri, f"dist_{name}", intri_path), intri_path, f"dist_{name}")
        T = _matrix(extri, f"T_{name}", extri_path)
        t = numbers(T, ((3,), (3, 1), (1, 3)), extri_path, f"T_{name}", "a 3x1 translation")
        R = _rotation(extri, name, extri_path)
        cameras.append(make_camera(K, R, t * length_unit_m, size, dist, extri_path, f"Rot_{name}"))
    return CameraRig.from_cameras(cameras), names


def write_easymocap(
    cameras: CameraRig, path: str | Path, names: Sequence[str] | None = None
) -> tuple[Path, Path]:
    """Write ``intri.yml`` and ``extri.yml`` (each atomically) into the folder ``path``.

    Args:
        cameras: cameras in view order.
        path: the folder (created when missing), or a path to one of the two files inside it.
        names: camera names made of letters, digits, ``_`` and ``-`` (default ``cam_00``, ``cam_01``...).

    Returns:
        The two paths written.

    Raises:
        FormatError: non-finite values, duplicate or unusable names.
    """
    cameras = check_writable(cameras, "EasyMocap YAML")
    names = camera_names(names, len(cameras), pattern=NAME_PATTERN)
    header = ["%YAML:1.0", "---", "names:", *(f'   - "{n}"' for n in names)]
    intri, extri = list(header), list(header)
    for cam, name in zip(cameras, names):
        intri += _matrix_lines(f"K_{name}", cam.K) + _matrix_lines(f"dist_{name}", cam.distortion[None, :])
        R = cam.R_cam_from_world
        extri += (
            _matrix_lines(f"R_{name}", rotvec_from_rotation(R)[:, None])
            + _matrix_lines(f"Rot_{name}", R)
            + _matrix_lines(f"T_{name}", cam.t_cam_from_world_m[:, None])
        )
    intri_path, extri_path = easymocap_paths(path)
    atomic_write_texts({intri_path: "\n".join(intri) + "\n", extri_path: "\n".join(extri) + "\n"})
    return intri_path, extri_path


def _matrix_lines(key: str, matrix: np.ndarray) -> list[str]:
    data = ", ".join(repr(float(x)) for x in matrix.ravel())
    rows, cols = matrix.shape
    return [f"{key}: !!opencv-matrix", f"   rows: {rows}", f"   cols: {cols}", "   dt: d", f"   data: [ {data} ]"]


def _open(path: Path) -> cv2.FileStorage:
    text = read_text(path)
    expected = "an OpenCV YAML file (%YAML:1.0, !!opencv-matrix nodes)"
    if not text.strip():
        raise FormatError(path, None, expected, "an empty file")
    try:
        storage = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as err:
        raise FormatError(path, None, expected, _cv_message(err)) from None
    if not storage.isOpened():
        raise FormatError(path, None, expected, "a file OpenCV cannot open")
    return storage


def _cv_message(err: BaseException) -> str:
    """The parser's own words of an OpenCV error (it may arrive wrapped in a SystemError)."""
    cause = err if isinstance(err, cv2.error) else (err.__cause__ or err)
    text = " ".join(str(cause).split())
    marker = "error: "
    return text[text.rfind(marker) + len(marker) :] if marker in text else text


def _names(storage: cv2.FileStorage, path: Path) -> list[str]:
    node = storage.getNode("names")
    if node.empty() or not node.isSeq() or node.size() == 0:
        got = "nothing" if node.empty() else "not a list"
        raise FormatError(path, "names", "a non-empty list of camera names", got)
    names = []
    for i in range(node.size()):
        item = node.at(i)
        if item.isString():
            names.append(item.string())
        elif item.isInt():
            names.append(str(int(item.real())))
        else:
            raise FormatError(path, f"names[{i}]", "a string or an integer", "another node type")
    if len(set(names)) != len(names):
        raise FormatError(path, "names", "distinct camera names", names)
    return names


def _matrix(storage: cv2.FileStorage, key: str, path: Path, *, required: bool = True) -> np.ndarray | None:
    node = storage.getNode(key)
    if node.empty():
        if not required:
            return None
        raise FormatError(path, key, "an !!opencv-matrix node", "nothing")
    if not node.isMap():
        raise FormatError(path, key, "an !!opencv-matrix node (rows, cols, dt, data)", "another node type")
    try:
        matrix = node.mat()
    except (cv2.error, SystemError) as err:
        expected = "an !!opencv-matrix node whose rows x cols match its data"
        raise FormatError(path, key, expected, f"OpenCV: {_cv_message(err)}") from None
    if matrix is None:
        raise FormatError(path, key, "an !!opencv-matrix node (rows, cols, dt, data)", "an unreadable matrix")
    return np.asarray(matrix, dtype=np.float64)


def _rotation(extri: cv2.FileStorage, name: str, path: Path) -> np.ndarray:
    """Rot_<name> when present (checked against R_<name> when both are), else the rotation of R_<name>."""
    rotvec = _matrix(extri, f"R_{name}", path, required=False)
    matrix = _matrix(extri, f"Rot_{name}", path, required=False)
    if rotvec is None and matrix is None:
        raise FormatError(path, f"R_{name}", f"a 3x1 Rodrigues vector R_{name} or a 3x3 matrix Rot_{name}", "nothing")
    from_rotvec = None
    if rotvec is not None:
        v = numbers(rotvec, ((3,), (3, 1), (1, 3)), path, f"R_{name}", "a 3x1 Rodrigues vector")
        from_rotvec = rotation_from_rotvec(v)
    if matrix is None:
        return from_rotvec  # type: ignore[return-value]
    R = rotation_matrix(numbers(matrix, ((3, 3),), path, f"Rot_{name}", "a 3x3 rotation matrix"), path, f"Rot_{name}")
    if from_rotvec is not None and np.abs(from_rotvec - R).max() > _RODRIGUES_AGREEMENT:
        raise FormatError(
            path,
            f"Rot_{name}",
            f"the rotation of R_{name} (within {_RODRIGUES_AGREEMENT:g})",
            f"max difference {np.abs(from_rotvec - R).max():.3g}",
        )
    return R
