"""COLMAP text model: ``cameras.txt``, ``images.txt`` (and an empty ``points3D.txt`` when writing).

``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS...`` per line. Models read: ``SIMPLE_PINHOLE`` (f cx cy),
``PINHOLE`` (fx fy cx cy), ``SIMPLE_RADIAL`` (f cx cy k), ``RADIAL`` (f cx cy k1 k2), ``OPENCV``
(fx fy cx cy k1 k2 p1 p2) and ``FULL_OPENCV`` (... k3 k4 k5 k6, with k4 = k5 = k6 = 0: the rational model is not
represented). ``images.txt``: two lines per image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` then the 2D
points (ignored, may be empty); the quaternion (Hamilton, scalar first) and translation are world -> camera, in the
model's length unit. Lines starting with ``#`` are comments.

Each *image* is one view (humancal cameras are static cameras: a multi-view rig registered as one image per camera),
in IMAGE_ID order, named by NAME.

Pixel convention: COLMAP puts the centre of the top-left pixel at (0.5, 0.5), OpenCV (and humancal) at (0, 0); with
``half_pixel_shift=True`` (default) the reader subtracts 0.5 from cx, cy and the writer adds it.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from humancal.camera import CameraRig, intrinsic_matrix
from humancal.formats._io import atomic_write_texts, read_text
from humancal.formats.cameras._checks import camera_names, check_writable, make_camera
from humancal.formats.errors import FormatError
from humancal.geometry.rotations import quat_xyzw_to_rotmat, rotmat_to_quat_xyzw

__all__ = ["COLMAP_MODELS", "read_colmap_text", "write_colmap_text", "colmap_paths"]

COLMAP_MODELS: dict[str, tuple[str, ...]] = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
"""Camera models read, with their parameter names in file order."""

_QUATERNION_TOLERANCE = 1e-5
"""Largest | |q| - 1 | accepted for a quaternion read from images.txt."""


def colmap_paths(path: str | Path) -> tuple[Path, Path, Path]:
    """(cameras.txt, images.txt, points3D.txt) of a model folder, or of one of its files."""
    path = Path(path)
    folder = path.parent if path.name in ("cameras.txt", "images.txt", "points3D.txt") else path
    return folder / "cameras.txt", folder / "images.txt", folder / "points3D.txt"


def read_colmap_text(
    path: str | Path, *, half_pixel_shift: bool = True, length_unit_m: float = 1.0
) -> tuple[CameraRig, list[str]]:
    """Read a COLMAP text model (one view per image).

    Args:
        path: the model folder, or its ``cameras.txt`` / ``images.txt``.
        half_pixel_shift: convert COLMAP's pixel-centre convention to OpenCV's (cx, cy minus 0.5).
        length_unit_m: metres per model unit (COLMAP models have an arbitrary scale unless aligned).

    Returns:
        cameras: the rig, views in IMAGE_ID order.
        names: the image names.

    Raises:
        FileNotFoundError: a file is missing.
        FormatError: a line with too few or non-numeric fields, an unsupported model, an unknown CAMERA_ID,
            a repeated id, a quaternion that is not unit length, no image.
    """
    cameras_path, images_path, _ = colmap_paths(path)
    if not (np.isfinite(length_unit_m) and length_unit_m > 0):
        raise ValueError(f"length_unit_m: expected a positive number of metres per model unit, got {length_unit_m!r}")
    intrinsics = _read_cameras_txt(cameras_path, 0.5 if half_pixel_shift else 0.0)
    lines = _data_lines(images_path, keep_blank=True)
    records = []
    i = 0
    while i < len(lines):
        lineno, line = lines[i]
        if not line.strip():
            i += 1
            continue
        records.append(_image_record(line, lineno, images_path, intrinsics))
        # The next line holds the image's 2D points (possibly blank); it must not be another image line.
        if i + 1 < len(lines) and _looks_like_image_line(lines[i + 1][1]):
            expected = f"the 2D points line of the image on line {lineno} (two lines per image)"
            raise FormatError(images_path, f"line {lines[i + 1][0]}", expected, "another image line")
        i += 2
    if not records:
        expected = "at least one image line 'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME'"
        raise FormatError(images_path, None, expected, "none")
    ids = [r[0] for r in records]
    if len(set(ids)) != len(ids):
        raise FormatError(images_path, "IMAGE_ID", "distinct image ids", sorted({i for i in ids if ids.count(i) > 1}))
    cameras, names = [], []
    for image_id, R, t, camera_id, name, field in sorted(records, key=lambda r: r[0]):
        K, dist, size = intrinsics[camera_id]
        cameras.append(make_camera(K, R, t * length_unit_m, size, dist, images_path, field))
        names.append(name)
    return CameraRig.from_cameras(cameras), names


def write_colmap_text(
    cameras: CameraRig,
    path: str | Path,
    names: Sequence[str] | None = None,
    *,
    half_pixel_shift: bool = True,
    length_unit_m: float = 1.0,
) -> tuple[Path, Path, Path]:
    """Write cameras as a COLMAP text model: one camera and one image per view, no 3D points (each file atomically).

    Models: ``PINHOLE`` without distortion, ``OPENCV`` when k3 = 0, else ``FULL_OPENCV`` (k4 = k5 = k6 = 0).

    Args:
        cameras: cameras in view order (CAMERA_ID and IMAGE_ID = view + 1).
        path: the model folder (created when missing).
        names: image names without whitespace (default ``cam_00``, ...).
        half_pixel_shift: add 0.5 to cx, cy (COLMAP's pixel-centre convention).
        length_unit_m: metres per written unit.

    Raises:
        FormatError: a camera with skew (COLMAP has none), non-finite values, bad names.
    """
    cameras = check_writable(cameras, "COLMAP text model")
    names = camera_names(names, len(cameras), pattern=r"\S+")
    shift = 0.5 if half_pixel_shift else 0.0
    cam_lines = [
        "# Camera list with one line of data per camera:",
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
        f"# Number of cameras: {len(cameras)}",
    ]
    img_lines = [
        "# Image list with two lines of data per image:",
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
        "#   POINTS2D[] as (X, Y, POINT3D_ID)",
        f"# Number of images: {len(cameras)}, mean observations per image: 0",
    ]
    for v, (cam, name) in enumerate(zip(cameras, names)):
        K, d = cam.K, cam.distortion
        if K[0, 1] != 0:
            raise FormatError(path, f"cameras[{v}].K", "zero skew (COLMAP models have none)", float(K[0, 1]))
        pinhole = [K[0, 0], K[1, 1], K[0, 2] + shift, K[1, 2] + shift]
        if not d.any():
            model, params = "PINHOLE", pinhole
        elif d[4] == 0:
            model, params = "OPENCV", pinhole + list(d[:4])
        else:
            model, params = "FULL_OPENCV", pinhole + list(d) + [0.0, 0.0, 0.0]
        cam_lines.append(f"{v + 1} {model} {cam.width_px} {cam.height_px} " + " ".join(_num(p) for p in params))
        x, y, z, w = rotmat_to_quat_xyzw(cam.R_cam_from_world)
        q = np.array([w, x, y, z]) * (1 if w >= 0 else -1)
        t = cam.t_cam_from_world_m / length_unit_m
        img_lines += [" ".join([str(v + 1), *(_num(c) for c in (*q, *t)), str(v + 1), name]), ""]
    points = [
        "# 3D point list with one line of data per point:",
        "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
        "# Number of points: 0, mean track length: 0",
    ]
    paths = colmap_paths(path)
    atomic_write_texts({p: "\n".join(lines) + "\n" for p, lines in zip(paths, (cam_lines, img_lines, points))})
    return paths


def _num(value: float) -> str:
    return repr(float(value))


def _data_lines(path: Path, *, keep_blank: bool = False) -> list[tuple[int, str]]:
    """(1-based line number, text) of the non-comment lines."""
    out = []
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        if line.lstrip().startswith("#") or (not keep_blank and not line.strip()):
            continue
        out.append((n, line))
    return out


def _read_cameras_txt(path: Path, shift: float) -> dict[int, tuple[np.ndarray, np.ndarray, tuple[int, int]]]:
    out = {}
    for lineno, line in _data_lines(path):
        tokens = line.split()
        field = f"line {lineno}"
        if len(tokens) < 4:
            raise FormatError(path, field, "'CAMERA_ID MODEL WIDTH HEIGHT PARAMS...'", f"{len(tokens)} fields")
        camera_id = _int(tokens[0], path, f"{field} CAMERA_ID")
        model = tokens[1]
        if model not in COLMAP_MODELS:
            raise FormatError(path, f"{field} MODEL", f"one of {list(COLMAP_MODELS)}", repr(model))
        width, height = _int(tokens[2], path, f"{field} WIDTH"), _int(tokens[3], path, f"{field} HEIGHT")
        if width <= 0 or height <= 0:
            raise FormatError(path, f"{field} WIDTH/HEIGHT", "positive integers", f"{width} x {height}")
        names = COLMAP_MODELS[model]
        if len(tokens) - 4 != len(names):
            expected = f"{len(names)} numbers for {model} ({' '.join(names)})"
            raise FormatError(path, f"{field} PARAMS", expected, f"{len(tokens) - 4}")
        p = dict(zip(names, (_float(tok, path, f"{field} {n}") for tok, n in zip(tokens[4:], names))))
        if any(p.get(k, 0.0) != 0 for k in ("k4", "k5", "k6")):
            expected = "zeros (the rational distortion model is not supported)"
            raise FormatError(path, f"{field} k4 k5 k6", expected, [p["k4"], p["k5"], p["k6"]])
        fx, fy = p.get("fx", p.get("f")), p.get("fy", p.get("f"))
        if not (fx > 0 and fy > 0):
            raise FormatError(path, f"{field} focal", "positive focal lengths", [fx, fy])
        K = intrinsic_matrix(fx, fy, p["cx"] - shift, p["cy"] - shift)
        dist = np.array([p.get("k1", 0.0), p.get("k2", 0.0), p.get("p1", 0.0), p.get("p2", 0.0), p.get("k3", 0.0)])
        if camera_id in out:
            raise FormatError(path, f"{field} CAMERA_ID", "distinct camera ids", camera_id)
        out[camera_id] = (K, dist, (width, height))
    if not out:
        raise FormatError(path, None, "at least one camera line", "none")
    return out


def _image_record(line: str, lineno: int, path: Path, intrinsics: dict) -> tuple:
    tokens = line.split()
    field = f"line {lineno}"
    if len(tokens) < 10:
        raise FormatError(path, field, "'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME'", f"{len(tokens)} fields")
    image_id = _int(tokens[0], path, f"{field} IMAGE_ID")
    q = np.array([_float(tok, path, f"{field} {n}") for tok, n in zip(tokens[1:5], ("QW", "QX", "QY", "QZ"))])
    t = np.array([_float(tok, path, f"{field} {n}") for tok, n in zip(tokens[5:8], ("TX", "TY", "TZ"))])
    camera_id = _int(tokens[8], path, f"{field} CAMERA_ID")
    if camera_id not in intrinsics:
        raise FormatError(path, f"{field} CAMERA_ID", f"one of the ids of cameras.txt {sorted(intrinsics)}", camera_id)
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > _QUATERNION_TOLERANCE:
        expected = f"a unit quaternion (|q| within {_QUATERNION_TOLERANCE:g} of 1)"
        raise FormatError(path, f"{field} QW QX QY QZ", expected, f"|q| = {norm:.6g}")
    R = quat_xyzw_to_rotmat(np.array([q[1], q[2], q[3], q[0]]))
    name = " ".join(tokens[9:])
    return image_id, R, t, camera_id, name, f"{field} QW QX QY QZ"


def _looks_like_image_line(line: str) -> bool:
    """An IMAGE_ID ... NAME line: 10+ fields, an integer first and a NAME that is not a number."""
    tokens = line.split()
    if len(tokens) < 10 or not re.fullmatch(r"\d+", tokens[0]):
        return False
    try:
        float(tokens[9])
    except ValueError:
        return True
    return False


def _int(token: str, path: Path, field: str) -> int:
    if not re.fullmatch(r"[+-]?\d+", token):
        raise FormatError(path, field, "an integer", repr(token))
    return int(token)


def _float(token: str, path: Path, field: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise FormatError(path, field, "a number", repr(token)) from None
    if not np.isfinite(value):
        raise FormatError(path, field, "a finite number", repr(token))
    return value
