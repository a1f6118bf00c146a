"""Users' own captures: per-view detector output (OpenPose JSON folders or COCO-style keypoint files) read into
the canonical tables, checked and summarised.

A capture is described by a :class:`CaptureConfig` (the options of a ``kind: capture`` sequence in a datasets
file)::

    format: openpose                  # or coco (AlphaPose, MMPose/RTMPose results, COCO annotation files)
    views: [cam1/, cam2/, cam3/]      # one folder (openpose) or file (coco) per view, in view order
    image_size: [1920, 1080]          # [width, height] for every view, or one pair per view
    skeleton: body25                  # optional where the array length tells it (needed for 25 points)
    cameras: {path: calib.toml, format: pose2sim}   # optional known cameras: evaluation only
    fps: 30                           # optional

Relative paths are relative to the datasets file's folder. Reading a capture drops (and counts) joints outside the
image (negative or beyond the width/height: trackers extrapolate them, no detector saw them) and placeholder
person entries without keypoints; every other problem is a :class:`~humancal.formats.FormatError` or
``ValueError`` naming the file and the field. Known cameras never reach the method: they become the
``gt_cameras`` table, used for evaluation and the known-camera reference rows only.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from humancal.camera import cameras_to_table
from humancal.formats import CAMERA_FORMATS, DETECTION_FORMATS, FormatError, read_cameras, read_detections
from humancal.formats.detections import PLACEHOLDERS_ATTR
from humancal.formats.skeletons import SKELETONS
from humancal.tables import empty_table, validate_table

__all__ = ["CAPTURE_FILE", "CaptureConfig", "CaptureSummary", "Capture", "load_capture", "parse_image_size",
           "parse_principal_point", "principal_points_option", "read_capture_folder"]

log = logging.getLogger(__name__)

PIXEL_EDGE_PX = 0.5
"""Pixel centres run from 0 to width - 1: a joint beyond half a pixel outside that range is off the image."""


def parse_image_size(text: str, where: str = "image size") -> tuple[int, int]:
    """``"1920x1080"`` as (width_px, height_px).

    Raises:
        ValueError: not two positive integers joined by ``x`` (the message names ``where``).
    """
    parts = str(text).lower().split("x")
    if len(parts) == 2 and all(p.strip().isdigit() for p in parts):
        w, h = int(parts[0]), int(parts[1])
        if w > 0 and h > 0:
            return w, h
    raise ValueError(f"{where}: expected WIDTHxHEIGHT in pixels (e.g. 1920x1080), got {text!r}")


def parse_principal_point(text: str, where: str = "principal point") -> tuple[float, float]:
    """``"963.5,541.2"`` as (cx_px, cy_px).

    Raises:
        ValueError: not two finite numbers joined by ``,`` (the message names ``where``).
    """
    parts = str(text).split(",")
    try:
        cx, cy = (float(p) for p in parts) if len(parts) == 2 else (np.nan, np.nan)
    except ValueError:
        cx = cy = np.nan
    if np.isfinite(cx) and np.isfinite(cy):
        return cx, cy
    raise ValueError(f"{where}: expected CX,CY in pixels (e.g. 963.5,541.2), got {text!r}")


def principal_points_option(value: object, image_sizes_px: Sequence[tuple[int, int]],
                            where: str = "principal_point") -> tuple[tuple[float, float], ...]:
    """Known principal points from an option: ``[cx, cy]`` for every view or one ``[cx, cy]`` per view, pixels, each
    inside its image (``0 <= cx <= width``, ``0 <= cy <= height``).

    Returns:
        (V,) (cx_px, cy_px), V = ``len(image_sizes_px)``.

    Raises:
        ValueError: another form, a count other than 1 or V, or a point outside its image (the message names
            ``where`` and the view).
    """
    def is_point(p: object) -> bool:
        return (isinstance(p, (list, tuple)) and len(p) == 2
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in p))

    V = len(image_sizes_px)
    if is_point(value):
        points = [tuple(float(x) for x in value)] * V  # type: ignore[union-attr]
    elif isinstance(value, (list, tuple)) and len(value) == V and all(is_point(p) for p in value):
        points = [tuple(float(x) for x in p) for p in value]  # type: ignore[union-attr]
    else:
        raise ValueError(f"{where}: expected [cx, cy] in pixels for every view or one [cx, cy] per view ({V}), "
                         f"got {value!r}")
    for v, ((cx, cy), (w, h)) in enumerate(zip(points, image_sizes_px)):
        if not (0.0 <= cx <= w and 0.0 <= cy <= h):
            raise ValueError(f"{where}: view {v}'s ({cx:g}, {cy:g}) is outside its {w}x{h} image")
    return tuple(points)  # type: ignore[return-value]


@dataclass(frozen=True)
class CaptureConfig:
    """Where a capture's detections (and, optionally, known cameras) are, and how to read them.

    Attributes:
        format: ``"openpose"`` (one JSON folder per view) or ``"coco"`` (one keypoint JSON file per view).
        views: (V,) absolute folder or file paths, in view order.
        image_sizes_px: (V,) (width_px, height_px) per view.
        skeleton: the detector's skeleton name (``None``: told from the array length where only one fits).
        cameras: known cameras file (evaluation only), or ``None``.
        cameras_format: its format (one of ``humancal.formats.CAMERA_FORMATS``; ``None``: from the file name).
        fps: frames per second, when known.
        principal_points_px: (V,) (cx_px, cy_px) per view when known (used by the calibration, which otherwise
            puts the principal point at the image centre), or ``None``.
    """

    format: str
    views: tuple[Path, ...]
    image_sizes_px: tuple[tuple[int, int], ...]
    skeleton: str | None = None
    cameras: Path | None = None
    cameras_format: str | None = None
    fps: float | None = None
    principal_points_px: tuple[tuple[float, float], ...] | None = None

    def __post_init__(self) -> None:
        if self.format not in DETECTION_FORMATS:
            raise ValueError(f"format: expected one of {list(DETECTION_FORMATS)}, got {self.format!r}")
        if not self.views:
            raise ValueError("views: expected at least one view (a folder or file per camera), got none")
        if len(self.image_sizes_px) != len(self.views):
            raise ValueError(
                f"image_size: expected one size for all views or one per view ({len(self.views)}), "
                f"got {len(self.image_sizes_px)}"
            )
        if self.skeleton is not None and self.skeleton not in SKELETONS:
            raise ValueError(f"skeleton: expected one of {sorted(SKELETONS)}, got {self.skeleton!r}")
        if self.cameras_format is not None and self.cameras_format not in CAMERA_FORMATS:
            raise ValueError(f"cameras.format: expected one of {list(CAMERA_FORMATS)}, got {self.cameras_format!r}")
        if self.fps is not None and not self.fps > 0:
            raise ValueError(f"fps: expected a positive number, got {self.fps!r}")
        if self.principal_points_px is not None:
            principal_points_option([list(p) for p in self.principal_points_px], self.image_sizes_px)

    @classmethod
    def from_options(cls, options: Mapping[str, Any], base_dir: Path | None) -> CaptureConfig:
        """The config of a ``kind: capture`` sequence's options (relative paths against ``base_dir``).

        Raises:
            ValueError: a missing or malformed option (the message names it).
        """
        def path(value: object, name: str) -> Path:
            if not isinstance(value, str) or not value:
                raise ValueError(f"{name}: expected a path, got {value!r}")
            p = Path(value).expanduser()
            return p if p.is_absolute() or base_dir is None else (base_dir / p)

        known = ("format", "views", "image_size", "skeleton", "cameras", "fps", "principal_point")
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise ValueError(f"unknown option(s) {unknown}; expected {', '.join(known)}")
        views = options.get("views")
        if not isinstance(views, list) or not views:
            raise ValueError(f"views: expected a list of paths (one per view), got {views!r}")
        size = options.get("image_size")
        if _is_size(size):
            sizes = [tuple(size)] * len(views)
        elif isinstance(size, list) and size and all(_is_size(s) for s in size):
            sizes = [tuple(s) for s in size]
        else:
            raise ValueError(f"image_size: expected [width, height] or one [width, height] per view, got {size!r}")
        cameras = options.get("cameras")
        cam_path, cam_format = None, None
        if cameras is not None:
            if not isinstance(cameras, dict) or "path" not in cameras:
                raise ValueError(f"cameras: expected {{path: FILE, format: FORMAT}}, got {cameras!r}")
            cam_path, cam_format = path(cameras["path"], "cameras.path"), cameras.get("format")
        return cls(
            format=options.get("format", "openpose"),
            views=tuple(path(v, f"views[{i}]") for i, v in enumerate(views)),
            image_sizes_px=tuple(sizes),  # type: ignore[arg-type]
            skeleton=options.get("skeleton"),
            cameras=cam_path,
            cameras_format=cam_format,
            fps=options.get("fps"),
            principal_points_px=(principal_points_option(options["principal_point"], sizes)  # type: ignore[arg-type]
                                 if options.get("principal_point") is not None else None),
        )

    def to_options(self) -> dict[str, Any]:
        """The options of a datasets file entry (absolute paths)."""
        sizes = {tuple(s) for s in self.image_sizes_px}
        options: dict[str, Any] = {
            "format": self.format,
            "views": [str(v) for v in self.views],
            "image_size": list(sizes.pop()) if len(sizes) == 1 else [list(s) for s in self.image_sizes_px],
        }
        if self.skeleton is not None:
            options["skeleton"] = self.skeleton
        if self.cameras is not None:
            options["cameras"] = {"path": str(self.cameras)}
            if self.cameras_format is not None:
                options["cameras"]["format"] = self.cameras_format
        if self.fps is not None:
            options["fps"] = float(self.fps)
        if self.principal_points_px is not None:
            points = {tuple(p) for p in self.principal_points_px}
            options["principal_point"] = (list(points.pop()) if len(points) == 1
                                          else [list(p) for p in self.principal_points_px])
        return options


def _is_size(value: object) -> bool:
    return (isinstance(value, (list, tuple)) and len(value) == 2
            and all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in value))


@dataclass(frozen=True)
class CaptureSummary:
    """What a capture holds, per view.

    Attributes:
        names: (V,) view names (folder or file stems).
        frames: (V,) frames with at least one detection.
        detections: (V,) person detections kept.
        placeholders: (V,) person entries without keypoints, skipped.
        off_image_joints: (V,) joints outside the image, dropped.
        skeleton: the detector skeleton (named, or told from the array length).
        known_cameras: whether known cameras come with it (evaluation only).
        total_frames: frames with a detection in any view.
    """

    names: tuple[str, ...]
    frames: tuple[int, ...]
    detections: tuple[int, ...]
    placeholders: tuple[int, ...]
    off_image_joints: tuple[int, ...]
    skeleton: str
    known_cameras: bool
    total_frames: int = 0

    def lines(self) -> list[str]:
        """The summary in words, one line per view and a last line for the capture."""
        out = [
            f"  view {v} {name}: {f} frames with detections, {d} detections, {p} placeholder entries skipped, "
            f"{o} off-image joints dropped"
            for v, (name, f, d, p, o) in enumerate(
                zip(self.names, self.frames, self.detections, self.placeholders, self.off_image_joints)
            )
        ]
        cams = "known cameras given (evaluation only)" if self.known_cameras else "no known cameras"
        out.append(f"  {len(self.names)} views, {self.total_frames} frames, {sum(self.detections)} detections, "
                   f"skeleton {self.skeleton}, {cams}")
        return out


@dataclass(frozen=True)
class Capture:
    """A capture's canonical tables and its summary.

    Attributes:
        detections: canonical ``detections`` table (on-image joints only).
        views: canonical ``views`` table.
        gt_cameras: canonical ``cameras`` table of the known cameras (empty when none).
        summary: counts per view.
    """

    detections: pd.DataFrame
    views: pd.DataFrame
    gt_cameras: pd.DataFrame
    summary: CaptureSummary


def load_capture(config: CaptureConfig, sequence: str) -> Capture:
    """Read, check and summarise a capture.

    Args:
        config: where the files are.
        sequence: the sequence name written in every row.

    Returns:
        The capture's tables and summary.

    Raises:
        FormatError: a bad detection or camera file (naming the file and field); known cameras that do not match
            the views (count, image size).
        FileNotFoundError: a folder or file does not exist.
        ValueError: no detection at all.
    """
    table = read_detections(list(config.views), config.format, sequence=sequence,
                            image_size=list(config.image_sizes_px), skeleton=config.skeleton)
    placeholders = dict(table.attrs.get(PLACEHOLDERS_ATTR, {}))
    sizes = dict(table.attrs.get("image_size_px", {}))
    if not len(table):
        raise FormatError(config.views[0], None, "at least one detected joint in the capture's files", "none")
    width = table["view"].map(lambda v: sizes[v][0]).to_numpy(float)
    height = table["view"].map(lambda v: sizes[v][1]).to_numpy(float)
    x, y = table["x_px"].to_numpy(), table["y_px"].to_numpy()
    off = ((x < -PIXEL_EDGE_PX) | (y < -PIXEL_EDGE_PX) | (x > width - 1 + PIXEL_EDGE_PX)
           | (y > height - 1 + PIXEL_EDGE_PX))
    off_per_view = table.loc[off, "view"].value_counts()
    if off.any():
        log.warning("%s: dropped %d joints outside the image (per view %s)", sequence, int(off.sum()),
                    off_per_view.to_dict())
    detections = table.loc[~off].reset_index(drop=True)
    V = len(config.views)
    names = [_view_name(p, v) for v, p in enumerate(config.views)]
    views = validate_table(pd.DataFrame({
        "sequence": sequence, "view": np.arange(V), "name": names,
        "width_px": [sizes[v][0] for v in range(V)], "height_px": [sizes[v][1] for v in range(V)],
    }), "views")
    gt_cameras = _known_cameras(config, sequence, sizes) if config.cameras is not None else empty_table("cameras")
    per_view = detections.groupby("view")
    dets = per_view.apply(lambda g: g.groupby(["frame", "det_id"]).ngroups, include_groups=False)
    frames = per_view["frame"].nunique()
    summary = CaptureSummary(
        names=tuple(names),
        frames=tuple(int(frames.get(v, 0)) for v in range(V)),
        detections=tuple(int(dets.get(v, 0)) for v in range(V)),
        placeholders=tuple(int(placeholders.get(v, 0)) for v in range(V)),
        off_image_joints=tuple(int(off_per_view.get(v, 0)) for v in range(V)),
        skeleton=config.skeleton or f"{table.attrs.get('skeleton') or 'unknown'} (told from the array length)",
        known_cameras=config.cameras is not None,
        total_frames=int(detections["frame"].nunique()),
    )
    return Capture(detections=detections, views=views, gt_cameras=gt_cameras, summary=summary)


def _view_name(path: Path, view: int) -> str:
    name = path.name if path.is_dir() else path.stem
    return name or f"view_{view}"


def _known_cameras(config: CaptureConfig, sequence: str, sizes: dict[int, tuple[int, int]]) -> pd.DataFrame:
    cameras = read_cameras(config.cameras, config.cameras_format)
    if len(cameras) != len(config.views):
        raise FormatError(config.cameras, None, f"{len(config.views)} cameras (one per view, in view order)",
                          f"{len(cameras)} cameras")
    for v, cam in enumerate(cameras):
        if (int(cam.width_px), int(cam.height_px)) != tuple(sizes[v]):
            raise FormatError(config.cameras, f"camera {v} image size",
                              f"the image size of view {v} ({sizes[v][0]}x{sizes[v][1]})",
                              f"{cam.width_px}x{cam.height_px}")
    return cameras_to_table(cameras, sequence)


CAPTURE_FILE = "capture.yaml"
"""The file that describes a capture folder (written last: its presence says the folder is complete)."""


def read_capture_folder(folder: Path) -> tuple[CaptureConfig, str]:
    """The config and sequence name of a self-describing capture folder.

    The folder holds the detections (one sub-folder of OpenPose JSON per view, or one COCO-style JSON file per
    view) and ``capture.yaml``: the options of :class:`CaptureConfig` (``views`` optional: by default the
    sub-folders, for ``format: openpose``, or the ``*.json`` files, for ``format: coco``, in sorted order; paths
    relative to the folder) and an optional ``sequence`` name (default ``"capture"``).

    Raises:
        FileNotFoundError: no ``capture.yaml``.
        ValueError: ``capture.yaml`` is not a YAML mapping of valid options (the message names the file and the
            option).
    """
    import yaml

    path = Path(folder) / CAPTURE_FILE
    try:
        options = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise FormatError(path, None, "valid YAML", str(err).replace("\n", " ")) from None
    if not isinstance(options, dict):
        raise FormatError(path, None, "a mapping of options (format, image_size, skeleton, cameras, fps)",
                          type(options).__name__)
    options = dict(options)
    sequence = str(options.pop("sequence", "capture"))
    if "views" not in options:
        fmt = options.get("format", "openpose")
        found = sorted(p for p in Path(folder).iterdir() if not p.name.startswith("."))
        found = [p for p in found if p.is_dir()] if fmt == "openpose" else [p for p in found if p.suffix == ".json"]
        options["views"] = [p.name for p in found]
    try:
        return CaptureConfig.from_options(options, Path(folder)), sequence
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None
