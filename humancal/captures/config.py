"""The options of a capture (:class:`CaptureConfig`): where its files are and what the user declared about them, as
a datasets file entry, ``capture.yaml`` or ``humancal add`` give them (``humancal.captures`` describes the YAML)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from humancal.captures.options import camera_file_option, is_size, named_numbers_option, principal_points_option
from humancal.formats import CAMERA_READ_FORMATS, DETECTION_FORMATS
from humancal.formats.skeletons import SKELETONS

__all__ = ["OPTION_NAMES", "CaptureConfig"]


OPTION_NAMES: dict[str, str] = {"views": "views", "image_size": "image_size", "skeleton": "skeleton",
                                "cameras_format": "cameras.format", "known_views": "cameras.views",
                                "reference_cameras_format": "reference_cameras.format", "drop_views": "drop_views",
                                "fps": "fps", "view_fps": "view_fps", "unsynced": "unsynced",
                                "time_offsets": "time_offsets", "videos": "videos"}
"""How messages name the capture options by default: as in a datasets file or ``capture.yaml``. The command line
passes its flags instead (``load_capture(..., option_names=...)``)."""


@dataclass(frozen=True)
class CaptureConfig:
    """Where a capture's detections (and, optionally, known cameras) are, and how to read them.

    Attributes:
        format: ``"openpose"`` (one JSON folder per view) or ``"coco"`` (one keypoint JSON file per view).
        views: (V,) absolute folder or file paths, in view order.
        image_sizes_px: (V,) (width_px, height_px) per view.
        skeleton: the detector's skeleton name (``None``: told from the array length where only one fits).
        cameras: known cameras file, or ``None``: the capture's cameras, used by the method instead of a
            calibration from the people (``docs/capture.md``, "Known cameras").
        cameras_format: its format (one of ``humancal.formats.CAMERA_READ_FORMATS``; ``None``: from the file name).
        known_views: the names of the views whose cameras ``cameras`` holds, in the file's order (``None``: every
            view, in view order); the other views are calibrated around them.
        refine_cameras: whether the body fit may refine the known cameras (default: they are held).
        reference_cameras: the true cameras of the views, one per view (evaluation only: the metric table's
            camera rows), or ``None``.
        reference_cameras_format: its format (``None``: from the file name).
        drop_views: names of views left out of the capture (e.g. one that cannot be calibrated).
        fps: frames per second of every view, when known.
        view_fps: (view name, frames per second) of the views whose rate differs from ``fps``.
        unsynced: the views were started by hand: their time offsets are estimated from the people's motion
            (:func:`humancal.sync.estimate_time_offsets`) unless ``time_offsets_s`` gives them.
        time_offsets_s: (view name, seconds): view ``v``'s frame ``n`` is at reference time ``n / fps_v +
            offset_v`` (views not named: 0); given by the user, or estimated by ``humancal add --unsynced``.
        principal_points_px: (V,) (cx_px, cy_px) per view when known (used by the calibration, which otherwise
            puts the principal point at the image centre), or ``None``.
        videos: (V,) the footage, a video file or an image folder per view in view order, or ``None``: what the
            overlays and the viewer draw on (:mod:`humancal.viewing.footage`); the method never reads it.
    """

    format: str
    views: tuple[Path, ...]
    image_sizes_px: tuple[tuple[int, int], ...]
    skeleton: str | None = None
    cameras: Path | None = None
    cameras_format: str | None = None
    fps: float | None = None
    principal_points_px: tuple[tuple[float, float], ...] | None = None
    known_views: tuple[str, ...] | None = None
    refine_cameras: bool = False
    reference_cameras: Path | None = None
    reference_cameras_format: str | None = None
    drop_views: tuple[str, ...] = ()
    view_fps: tuple[tuple[str, float], ...] = ()
    unsynced: bool = False
    time_offsets_s: tuple[tuple[str, float], ...] = ()
    videos: tuple[Path, ...] | None = None

    @property
    def needs_sync(self) -> bool:
        """Whether the views' frames must be moved to one clock (declared unsynced, offsets or per-view rates)."""
        return self.unsynced or bool(self.time_offsets_s) or bool(self.view_fps)

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
        for name, fmt in (("cameras.format", self.cameras_format),
                          ("reference_cameras.format", self.reference_cameras_format)):
            if fmt is not None and fmt not in CAMERA_READ_FORMATS:
                raise ValueError(f"{name}: expected one of {list(CAMERA_READ_FORMATS)}, got {fmt!r}")
        if self.cameras is None and (self.known_views is not None or self.refine_cameras):
            raise ValueError("cameras.views and cameras.refine need known cameras (cameras.path)")
        if self.fps is not None and not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps: expected a positive number, got {self.fps!r}")
        for name, pairs, positive in (("view_fps", self.view_fps, True), ("time_offsets", self.time_offsets_s, False)):
            values = [v for _, v in pairs]
            if len({n for n, _ in pairs}) != len(pairs) or not all(np.isfinite(v) and (v > 0 or not positive)
                                                                    for v in values):
                raise ValueError(f"{name}: expected one {'positive ' if positive else ''}number per named view, "
                                 f"got {dict(pairs)!r}")
        if self.principal_points_px is not None:
            principal_points_option([list(p) for p in self.principal_points_px], self.image_sizes_px)
        if self.videos is not None and len(self.videos) != len(self.views):
            raise ValueError(f"videos: expected one video file or image folder per view ({len(self.views)}), "
                             f"got {len(self.videos)}")

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

        known = ("format", "views", "image_size", "skeleton", "cameras", "reference_cameras", "drop_views", "fps",
                 "principal_point", "view_fps", "unsynced", "time_offsets", "videos")
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise ValueError(f"unknown option(s) {unknown}; expected {', '.join(known)}")
        views = options.get("views")
        if not isinstance(views, list) or not views:
            raise ValueError(f"views: expected a list of paths (one per view), got {views!r}")
        size = options.get("image_size")
        if is_size(size):
            sizes = [tuple(size)] * len(views)
        elif isinstance(size, list) and size and all(is_size(s) for s in size):
            sizes = [tuple(s) for s in size]
        else:
            raise ValueError(f"image_size: expected [width, height] or one [width, height] per view, got {size!r}")
        known = camera_file_option(options.get("cameras"), "cameras", path, ("views", "refine"))
        reference = camera_file_option(options.get("reference_cameras"), "reference_cameras", path, ())
        drop = options.get("drop_views", [])
        if not (isinstance(drop, list) and all(isinstance(n, str) for n in drop)):
            raise ValueError(f"drop_views: expected a list of view names, got {drop!r}")
        views_known = known.get("views")
        if views_known is not None and not (isinstance(views_known, list) and all(isinstance(n, str)
                                                                                   for n in views_known)):
            raise ValueError(f"cameras.views: expected a list of view names, got {views_known!r}")
        fps = options.get("fps")
        if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float))):
            raise ValueError(f"fps: expected a number (frames per second; per view: view_fps), got {fps!r}")
        unsynced = options.get("unsynced", False)
        if not isinstance(unsynced, bool):
            raise ValueError(f"unsynced: expected true or false, got {unsynced!r}")
        videos = options.get("videos")
        if videos is not None and not isinstance(videos, list):
            raise ValueError(f"videos: expected a list of paths (a video file or image folder per view), got {videos!r}")
        return cls(
            format=options.get("format", "openpose"),
            views=tuple(path(v, f"views[{i}]") for i, v in enumerate(views)),
            image_sizes_px=tuple(sizes),  # type: ignore[arg-type]
            skeleton=options.get("skeleton"),
            cameras=known.get("path"),
            cameras_format=known.get("format"),
            known_views=tuple(views_known) if views_known is not None else None,
            refine_cameras=bool(known.get("refine", False)),
            reference_cameras=reference.get("path"),
            reference_cameras_format=reference.get("format"),
            drop_views=tuple(drop),
            fps=fps,
            view_fps=named_numbers_option(options.get("view_fps", {}), "view_fps", positive=True),
            unsynced=unsynced,
            time_offsets_s=named_numbers_option(options.get("time_offsets", {}), "time_offsets", positive=False),
            principal_points_px=(principal_points_option(options["principal_point"], sizes)  # type: ignore[arg-type]
                                 if options.get("principal_point") is not None else None),
            videos=None if videos is None else tuple(path(v, f"videos[{i}]") for i, v in enumerate(videos)),
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
            if self.known_views is not None:
                options["cameras"]["views"] = list(self.known_views)
            if self.refine_cameras:
                options["cameras"]["refine"] = True
        if self.reference_cameras is not None:
            options["reference_cameras"] = {"path": str(self.reference_cameras)}
            if self.reference_cameras_format is not None:
                options["reference_cameras"]["format"] = self.reference_cameras_format
        if self.drop_views:
            options["drop_views"] = list(self.drop_views)
        if self.fps is not None:
            options["fps"] = float(self.fps)
        if self.view_fps:
            options["view_fps"] = {name: float(value) for name, value in self.view_fps}
        if self.unsynced:
            options["unsynced"] = True
        if self.time_offsets_s:
            options["time_offsets"] = {name: float(value) for name, value in self.time_offsets_s}
        if self.principal_points_px is not None:
            points = {tuple(p) for p in self.principal_points_px}
            options["principal_point"] = (list(points.pop()) if len(points) == 1
                                          else [list(p) for p in self.principal_points_px])
        if self.videos is not None:
            options["videos"] = [str(v) for v in self.videos]
        return options
