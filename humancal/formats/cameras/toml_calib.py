"""Pose2Sim / anipose calibration TOML.

One table per camera (any table name but ``metadata``), in file order::

    [cam_01]
    name = "cam_01"
    size = [ 1920.0, 1080.0]                  # width, height in pixels
    matrix = [ [ fx, 0.0, cx], [ 0.0, fy, cy], [ 0.0, 0.0, 1.0]]
    distortions = [ k1, k2, p1, p2]           # OpenCV order; anipose writes 5 (k3 too)
    rotation = [ rx, ry, rz]                  # Rodrigues vector, world -> camera (OpenCV rvec)
    translation = [ tx, ty, tz]               # world -> camera (OpenCV tvec)
    fisheye = false

    [metadata]
    adjusted = false
    error = 0.0

Both tools use OpenCV's ``x_cam = R(rvec) x_world + tvec``. Pose2Sim writes the translation in metres (it divides
its board units by 1000). anipose writes it in the unit of its calibration board (``square_length`` of its
config, usually millimetres), and names the tables ``cam_0``, ``cam_1``...: pass ``length_unit_m=0.001`` for a
board measured in millimetres. Fisheye cameras (``fisheye = true``, Kannala-Brandt distortion) cannot be
represented by :class:`humancal.camera.Camera` and are refused. Pose2Sim's world is Z up; anipose's is whatever the
board defined.
"""

from __future__ import annotations

import json
import re
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np

from humancal.camera import CameraRig
from humancal.formats._io import atomic_write_text, read_text
from humancal.formats.cameras._checks import (
    camera_names,
    check_writable,
    distortion5,
    size_pair,
    intrinsic_matrix,
    make_camera,
    numbers,
    rotation_from_rotvec,
    rotvec_from_rotation,
)
from humancal.formats.errors import FormatError, missing_field

__all__ = ["read_toml_calibration", "write_toml_calibration"]

Flavor = Literal["pose2sim", "anipose"]

_VECTOR3 = ((3,), (3, 1), (1, 3))


def read_toml_calibration(path: str | Path, *, length_unit_m: float = 1.0) -> tuple[CameraRig, list[str]]:
    """Read a Pose2Sim or anipose calibration TOML.

    Args:
        path: the ``.toml`` file.
        length_unit_m: metres per unit of ``translation`` (1 for Pose2Sim; anipose: the board's unit, e.g. 0.001).

    Returns:
        cameras: the rig, views in file order.
        names: each camera's ``name`` (the table name when ``name`` is absent).

    Raises:
        FileNotFoundError: no such file.
        FormatError: invalid TOML; no camera table; a missing or malformed field (non-numeric, non-finite, wrong
            length); a fisheye camera; duplicate names.
    """
    path = Path(path)
    if not (np.isfinite(length_unit_m) and length_unit_m > 0):
        raise ValueError(f"length_unit_m: expected a positive number of metres per file unit, got {length_unit_m!r}")
    try:
        data = tomllib.loads(read_text(path))
    except tomllib.TOMLDecodeError as err:
        raise FormatError(path, None, "valid TOML", str(err)) from None
    tables = {k: v for k, v in data.items() if k != "metadata"}
    if not tables:
        raise FormatError(path, None, "at least one camera table ([cam_01] with size, matrix, ...)", "none")
    cameras, names = [], []
    for key, cam in tables.items():
        if not isinstance(cam, dict):
            raise FormatError(path, key, "a camera table", type(cam).__name__)
        for field in ("size", "matrix", "distortions", "rotation", "translation"):
            if field not in cam:
                raise missing_field(path, f"{key}.{field}")
        if cam.get("fisheye", False) is not False:
            raise FormatError(path, f"{key}.fisheye", "false (fisheye distortion is not supported)", cam.get("fisheye"))
        name = cam.get("name", key)
        if not isinstance(name, str):
            raise FormatError(path, f"{key}.name", "a string", name)
        K = intrinsic_matrix(cam["matrix"], path, f"{key}.matrix")
        dist = distortion5(cam["distortions"], path, f"{key}.distortions")
        rotvec = numbers(cam["rotation"], _VECTOR3, path, f"{key}.rotation", "3 numbers (Rodrigues vector)")
        t = numbers(cam["translation"], _VECTOR3, path, f"{key}.translation", "3 numbers")
        size = size_pair(cam["size"], path, f"{key}.size")
        R = rotation_from_rotvec(rotvec)
        cameras.append(make_camera(K, R, t * length_unit_m, size, dist, path, f"{key}.rotation"))
        names.append(name)
    if len(set(names)) != len(names):
        raise FormatError(path, "name", "distinct camera names", names)
    return CameraRig.from_cameras(cameras), names


def write_toml_calibration(
    cameras: CameraRig,
    path: str | Path,
    names: Sequence[str] | None = None,
    *,
    flavor: Flavor = "pose2sim",
    length_unit_m: float = 1.0,
) -> Path:
    """Write cameras as a Pose2Sim (default) or anipose calibration TOML (atomically).

    Args:
        cameras: cameras in view order.
        path: the ``.toml`` file.
        names: camera names (default ``cam_00``, ``cam_01``...).
        flavor: ``"pose2sim"``: tables named after the cameras, 4 distortion numbers (5 when k3 is not 0), image size
            as floats, ``[metadata] adjusted/error``; ``"anipose"``: tables ``cam_0``, ``cam_1``..., 5 distortion
            numbers, integer image size, empty ``[metadata]``.
        length_unit_m: metres per unit of the written ``translation`` (1 for Pose2Sim).

    Raises:
        FormatError: non-finite values, duplicate names, a Pose2Sim camera named ``metadata``.
    """
    cameras = check_writable(cameras, "calibration TOML")
    names = camera_names(names, len(cameras))
    if flavor == "pose2sim" and "metadata" in names:
        raise FormatError(path, "names", "names other than 'metadata' (the reserved table of the format)", names)
    if flavor not in ("pose2sim", "anipose"):
        raise ValueError(f"flavor: expected 'pose2sim' or 'anipose', got {flavor!r}")
    if not (np.isfinite(length_unit_m) and length_unit_m > 0):
        raise ValueError(f"length_unit_m: expected a positive number of metres per file unit, got {length_unit_m!r}")
    lines = []
    for i, (cam, name) in enumerate(zip(cameras, names)):
        table = name if flavor == "pose2sim" else f"cam_{i}"
        dist = cam.distortion if flavor == "anipose" or cam.distortion[4] != 0 else cam.distortion[:4]
        size = [float(cam.width_px), float(cam.height_px)] if flavor == "pose2sim" else [cam.width_px, cam.height_px]
        lines += [
            f"[{_key(table)}]",
            f"name = {_string(name)}",
            f"size = {_array(size)}",
            f"matrix = [ {', '.join(_array(row) for row in cam.K)}]",
            f"distortions = {_array(dist)}",
            f"rotation = {_array(rotvec_from_rotation(cam.R_cam_from_world))}",
            f"translation = {_array(cam.t_cam_from_world_m / length_unit_m)}",
            "fisheye = false",
            "",
        ]
    lines += ["[metadata]", *(["adjusted = false", "error = 0.0"] if flavor == "pose2sim" else []), ""]
    return atomic_write_text(path, "\n".join(lines))


def _key(name: str) -> str:
    """A TOML key: bare when it can be, else a quoted string."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else _string(name)


def _string(text: str) -> str:
    # A JSON string is a valid TOML basic string (same escapes).
    return json.dumps(text, ensure_ascii=False)


def _array(values) -> str:
    return "[ " + ", ".join(_number(v) for v in values) + "]"


def _number(value) -> str:
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    # repr round-trips a float exactly and is valid TOML (1.0, 1e-05, -2.5e+20).
    text = repr(float(value))
    return text if any(c in text for c in ".e") else text + ".0"
