"""Camera files of other tools and datasets, read into and written from :class:`humancal.camera.CameraRig` rigs.

Formats (``format=``):

``"humancal"``   humancal's versioned JSON (:mod:`.humancal_json`)
``"shelf"``      Shelf / Campus ``calibration.json`` (:mod:`.shelf`)
``"pose2sim"``   Pose2Sim calibration TOML (:mod:`.toml_calib`)
``"anipose"``    anipose calibration TOML (same reader; translation in the board's unit, see ``length_unit_m``)
``"easymocap"``  EasyMocap ``intri.yml`` + ``extri.yml`` (:mod:`.easymocap`; image size is an argument)
``"colmap"``     COLMAP text model (:mod:`.colmap`)
``"qualisys"``   Qualisys ``.qca.txt`` calibration (:mod:`.qualisys`; read only)

Every reader converts to the house convention (``docs/conventions.md``): world -> camera rotation matrices,
translations in metres, OpenCV pixel centres. Every write is atomic per file (temporary file in the same folder,
then ``os.replace``) and builds all its text before touching any file.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from humancal.camera import CameraRig
from humancal.formats.cameras.colmap import read_colmap_text, write_colmap_text
from humancal.formats.cameras.easymocap import read_easymocap, write_easymocap
from humancal.formats.cameras.humancal_json import FORMAT_NAME, read_humancal_cameras, write_humancal_cameras
from humancal.formats.cameras.qualisys import read_qualisys_calibration
from humancal.formats.cameras.shelf import read_shelf_calibration, write_shelf_calibration
from humancal.formats.cameras.toml_calib import read_toml_calibration, write_toml_calibration
from humancal.formats.errors import FormatError

__all__ = [
    "CAMERA_FORMATS",
    "CAMERA_READ_FORMATS",
    "infer_camera_format",
    "read_cameras",
    "read_cameras_with_names",
    "write_cameras",
    "read_colmap_text",
    "write_colmap_text",
    "read_easymocap",
    "write_easymocap",
    "read_humancal_cameras",
    "read_qualisys_calibration",
    "write_humancal_cameras",
    "read_shelf_calibration",
    "write_shelf_calibration",
    "read_toml_calibration",
    "write_toml_calibration",
]

CAMERA_FORMATS = ("humancal", "shelf", "pose2sim", "anipose", "easymocap", "colmap")
"""Formats ``read_cameras`` and ``write_cameras`` understand."""

CAMERA_READ_FORMATS = (*CAMERA_FORMATS, "qualisys")
"""Formats ``read_cameras`` understands (``qualisys`` is read only)."""


def infer_camera_format(path: str | Path) -> str:
    """The camera format of ``path`` from its name, extension or (for ``.json``) its top-level keys.

    Rules: a folder holding ``intri.yml`` -> easymocap, holding ``cameras.txt`` -> colmap; ``intri.yml`` /
    ``extri.yml`` -> easymocap; ``cameras.txt`` / ``images.txt`` -> colmap; ``.toml`` -> pose2sim (read the same
    way as anipose); ``.qca.txt`` -> qualisys; ``.json`` with ``"format": "humancal.cameras"`` -> humancal, with
    objects holding ``K`` and ``RT`` -> shelf.

    Raises:
        FileNotFoundError: the path does not exist.
        FormatError: no rule applies (the message lists the known formats).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    unknown = (f"a camera file whose format can be told from its name, or its format named (one of "
               f"{list(CAMERA_READ_FORMATS)})")
    if path.is_dir():
        if (path / "intri.yml").is_file():
            return "easymocap"
        if (path / "cameras.txt").is_file():
            return "colmap"
        raise FormatError(path, None, unknown, "a folder with neither intri.yml nor cameras.txt")
    if path.name in ("intri.yml", "extri.yml"):
        return "easymocap"
    if path.name in ("cameras.txt", "images.txt", "points3D.txt"):
        return "colmap"
    if path.suffix.lower() == ".toml":
        return "pose2sim"
    if path.name.lower().endswith(".qca.txt"):
        return "qualisys"
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise FormatError(path, None, "valid JSON (to tell its camera format)", "unparsable text") from None
        if isinstance(data, dict) and data.get("format") == FORMAT_NAME:
            return "humancal"
        cameras = data.values() if isinstance(data, dict) else ()
        if cameras and all(isinstance(v, dict) and {"K", "RT"} <= set(v) for v in cameras):
            return "shelf"
    raise FormatError(path, None, unknown, repr(path.name))


def read_cameras_with_names(path: str | Path, format: str | None = None, **options) -> tuple[CameraRig, list[str]]:
    """Read cameras and their names from ``path``.

    Args:
        path: the camera file (or folder, for easymocap and colmap).
        format: one of :data:`CAMERA_READ_FORMATS`; ``None`` infers it (:func:`infer_camera_format`).
        **options: passed to the format's reader: ``length_unit_m`` (pose2sim, anipose, easymocap, colmap),
            ``image_size`` (easymocap, required there), ``half_pixel_shift`` (colmap).

    Returns:
        the rig of the cameras and their names, in the file's camera order.

    Raises:
        FormatError: unknown format, or a bad file (the message names file and field).
        FileNotFoundError: the file does not exist.
        TypeError: an option the format's reader does not take.
    """
    fmt = infer_camera_format(path) if format is None else _known(format, CAMERA_READ_FORMATS)
    reader = {
        "humancal": read_humancal_cameras,
        "shelf": read_shelf_calibration,
        "pose2sim": read_toml_calibration,
        "anipose": read_toml_calibration,
        "easymocap": read_easymocap,
        "colmap": read_colmap_text,
        "qualisys": read_qualisys_calibration,
    }[fmt]
    return reader(path, **options)


def read_cameras(path: str | Path, format: str | None = None, **options) -> CameraRig:
    """Read cameras from ``path`` (see :func:`read_cameras_with_names`, which also returns the names)."""
    return read_cameras_with_names(path, format, **options)[0]


def write_cameras(
    cameras: CameraRig, path: str | Path, format: str, names: Sequence[str] | None = None, **options
) -> Path:
    """Write cameras to ``path`` in ``format``.

    Args:
        cameras: the rig to write (cameras in view order; a list of cameras is taken as one).
        path: the file (folder for easymocap and colmap).
        format: one of :data:`CAMERA_FORMATS`.
        names: camera names (default ``cam_00``, ``cam_01``...; shelf accepts only ``"0", "1", ...``).
        **options: passed to the format's writer: ``length_unit_m`` (pose2sim, anipose, colmap),
            ``half_pixel_shift`` (colmap).

    Returns:
        The path written (the folder for easymocap and colmap).

    Raises:
        FormatError: unknown format, or cameras the format cannot hold (distortion in shelf, skew in colmap, ...).
    """
    fmt = _known(format)
    path = Path(path)
    if fmt == "humancal":
        return write_humancal_cameras(cameras, path, names, **options)
    if fmt == "shelf":
        return write_shelf_calibration(cameras, path, names, **options)
    if fmt in ("pose2sim", "anipose"):
        return write_toml_calibration(cameras, path, names, flavor=fmt, **options)
    if fmt == "easymocap":
        return write_easymocap(cameras, path, names, **options)[0].parent
    return write_colmap_text(cameras, path, names, **options)[0].parent


def _known(format: str, known: tuple[str, ...] = CAMERA_FORMATS) -> str:
    if format not in known:
        read_only = sorted(set(CAMERA_READ_FORMATS) - set(known))
        note = f" ({', '.join(read_only)}: read only)" if read_only and format in read_only else ""
        raise FormatError(None, "format", f"one of {list(known)}{note}", repr(format))
    return format
