"""humancal's own camera file: versioned, self-describing JSON.

::

    {
      "format": "humancal.cameras",
      "version": 1,
      "convention": {...},              # CONVENTION_V1, checked on reading
      "cameras": [
        {"name": "cam_00", "width_px": 1920, "height_px": 1080,
         "K": [[fx, s, cx], [0, fy, cy], [0, 0, 1]],
         "distortion": [k1, k2, p1, p2, k3],
         "R_cam_from_world": [[...], [...], [...]],
         "t_cam_from_world_m": [tx, ty, tz]}
      ]
    }

Numbers are written with Python's shortest round-trip representation, so write-then-read is exact.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from humancal.camera import CameraRig
from humancal.formats._io import atomic_write_text, load_json
from humancal.formats.cameras._checks import (
    camera_names,
    check_writable,
    distortion5,
    size_pair,
    intrinsic_matrix,
    make_camera,
    numbers,
)
from humancal.formats.errors import FormatError, missing_field

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "CONVENTION_V1", "read_humancal_cameras", "write_humancal_cameras"]

FORMAT_NAME = "humancal.cameras"
FORMAT_VERSION = 1

CONVENTION_V1: dict[str, str] = {
    "world": "metres, right-handed, Z up",
    "camera": "OpenCV pinhole: x right, y down, z forward",
    "extrinsics": "x_cam = R_cam_from_world @ x_world + t_cam_from_world_m",
    "intrinsics": "K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]] in pixels; pixel centres at integer coordinates",
    "distortion": "OpenCV (k1, k2, p1, p2, k3)",
}
"""The conventions a version-1 file declares (and must declare to be read)."""


def read_humancal_cameras(path: str | Path) -> tuple[CameraRig, list[str]]:
    """Read a ``humancal.cameras`` JSON file.

    Returns:
        cameras: the rig, views in file order.
        names: their names.

    Raises:
        FileNotFoundError: no such file.
        FormatError: invalid JSON; another format or version; a convention other than :data:`CONVENTION_V1`;
            a missing or malformed camera field; a non-orthonormal rotation; duplicate names.
    """
    path = Path(path)
    data = load_json(path)
    if not isinstance(data, dict):
        raise FormatError(path, None, f"a JSON object with format '{FORMAT_NAME}'", type(data).__name__)
    header = (
        ("format", FORMAT_NAME, repr(FORMAT_NAME)),
        ("version", FORMAT_VERSION, f"{FORMAT_VERSION} (files of other versions need another humancal)"),
        ("convention", CONVENTION_V1, f"the version-{FORMAT_VERSION} convention {CONVENTION_V1}"),
    )
    for key, value, expected in header:
        if data.get(key) != value:
            raise FormatError(path, key, expected, repr(data[key]) if key in data else "nothing")
    entries = data.get("cameras")
    if not isinstance(entries, list) or not entries:
        raise FormatError(path, "cameras", "a non-empty list of cameras", entries if entries is not None else "missing")
    cameras, names = [], []
    for i, cam in enumerate(entries):
        where = f"cameras[{i}]"
        if not isinstance(cam, dict):
            raise FormatError(path, where, "an object", type(cam).__name__)
        for field in ("name", "width_px", "height_px", "K", "distortion", "R_cam_from_world", "t_cam_from_world_m"):
            if field not in cam:
                raise missing_field(path, f"{where}.{field}")
        if not isinstance(cam["name"], str):
            raise FormatError(path, f"{where}.name", "a string", cam["name"])
        size = size_pair([cam["width_px"], cam["height_px"]], path, f"{where}.width_px/height_px")
        K = intrinsic_matrix(cam["K"], path, f"{where}.K", shapes=((3, 3),))
        dist = distortion5(cam["distortion"], path, f"{where}.distortion", lengths=(5,))
        R = numbers(cam["R_cam_from_world"], ((3, 3),), path, f"{where}.R_cam_from_world", "a 3x3 matrix (3 rows)")
        t = numbers(cam["t_cam_from_world_m"], ((3,),), path, f"{where}.t_cam_from_world_m", "3 numbers (metres)")
        cameras.append(make_camera(K, R, t, size, dist, path, f"{where}.R_cam_from_world"))
        names.append(cam["name"])
    if len(set(names)) != len(names):
        raise FormatError(path, "cameras[].name", "distinct camera names", names)
    return CameraRig.from_cameras(cameras), names


def write_humancal_cameras(cameras: CameraRig, path: str | Path, names: Sequence[str] | None = None) -> Path:
    """Write cameras as a ``humancal.cameras`` JSON file (atomically).

    Args:
        cameras: cameras in view order.
        path: the file to write.
        names: camera names (default ``cam_00``, ``cam_01``...).

    Raises:
        FormatError: non-finite values, duplicate names.
    """
    cameras = check_writable(cameras, FORMAT_NAME)
    names = camera_names(names, len(cameras))
    data = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "convention": CONVENTION_V1,
        "cameras": [
            {
                "name": name,
                "width_px": cam.width_px,
                "height_px": cam.height_px,
                "K": cam.K.tolist(),
                "distortion": cam.distortion.tolist(),
                "R_cam_from_world": cam.R_cam_from_world.tolist(),
                "t_cam_from_world_m": cam.t_cam_from_world_m.tolist(),
            }
            for cam, name in zip(cameras, names)
        ],
    }
    return atomic_write_text(path, json.dumps(data, indent=2) + "\n")
