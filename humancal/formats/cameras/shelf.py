"""Shelf / Campus ``calibration.json`` (as 4D Association ships it).

A JSON object keyed ``"0"``, ``"1"``, ... (one per camera, view order), each
``{"K": 9 numbers row-major, "RT": 12 numbers row-major [R | t], "imgSize": [width, height]}`` with ``R``, ``t``
world -> camera (``x_cam = R x_world + t``), ``t`` in metres, world Z up. The format has no distortion.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from humancal.camera import CameraRig
from humancal.formats._io import atomic_write_text, load_json
from humancal.formats.cameras._checks import (
    check_writable,
    size_pair,
    intrinsic_matrix,
    make_camera,
    numbers,
)
from humancal.formats.errors import FormatError, missing_field

__all__ = ["read_shelf_calibration", "write_shelf_calibration"]


def read_shelf_calibration(path: str | Path) -> tuple[CameraRig, list[str]]:
    """Read a Shelf/Campus ``calibration.json``.

    Returns:
        cameras: the rig, views in key order ``"0"``, ``"1"``, ... (no distortion).
        names: the keys.

    Raises:
        FileNotFoundError: no such file.
        FormatError: invalid JSON; not an object keyed "0".."N-1"; a camera without K (9 numbers), RT (12 numbers)
            or imgSize ([width, height]); non-finite values; a non-orthonormal rotation.
    """
    path = Path(path)
    data = load_json(path)
    if not isinstance(data, dict) or not data:
        raise FormatError(path, None, 'a JSON object keyed "0", "1", ... (one per camera)', type(data).__name__)
    expected_keys = [str(i) for i in range(len(data))]
    if sorted(data, key=lambda k: (len(k), k)) != expected_keys:
        raise FormatError(path, None, f"camera keys {expected_keys}", f"{list(data)}")
    cameras = []
    for key in expected_keys:
        cam = data[key]
        if not isinstance(cam, dict):
            raise FormatError(path, key, "an object with K, RT and imgSize", type(cam).__name__)
        for field in ("K", "RT", "imgSize"):
            if field not in cam:
                raise missing_field(path, f"{key}.{field}")
        K = intrinsic_matrix(cam["K"], path, f"{key}.K", shapes=((9,), (3, 3)))
        what = "12 numbers (row-major 3x4 [R|t], world->camera, m)"
        RT = numbers(cam["RT"], ((12,), (3, 4)), path, f"{key}.RT", what).reshape(3, 4)
        size = size_pair(cam["imgSize"], path, f"{key}.imgSize")
        cameras.append(make_camera(K, RT[:, :3], RT[:, 3], size, np.zeros(5), path, f"{key}.RT"))
    return CameraRig.from_cameras(cameras), expected_keys


def write_shelf_calibration(cameras: CameraRig, path: str | Path, names: Sequence[str] | None = None) -> Path:
    """Write cameras as a Shelf ``calibration.json`` (atomically).

    Args:
        cameras: cameras in view order; they must have no distortion (the format has none).
        path: the file to write.
        names: must be ``None`` or ``"0", "1", ...``: the format keys cameras by view index only.

    Raises:
        FormatError: a camera with distortion, names other than the indices, non-finite values.
    """
    cameras = check_writable(cameras, "Shelf calibration")
    keys = [str(i) for i in range(len(cameras))]
    if names is not None and [str(n) for n in names] != keys:
        raise FormatError(path, "names", f"None or {keys} (Shelf calibration keys cameras by index)", list(names))
    data = {}
    for key, cam in zip(keys, cameras):
        if np.any(cam.distortion != 0):
            raise FormatError(path, f"{key}.distortion", "zero distortion (the Shelf format has none)", cam.distortion)
        RT = np.hstack([cam.R_cam_from_world, cam.t_cam_from_world_m[:, None]])
        data[key] = {
            "K": [float(x) for x in cam.K.ravel()],
            "RT": [float(x) for x in RT.ravel()],
            "imgSize": [cam.width_px, cam.height_px],
        }
    return atomic_write_text(path, json.dumps(data, indent=2) + "\n")
