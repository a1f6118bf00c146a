"""Users' own captures: per-view detector output (OpenPose JSON folders or COCO-style keypoint files) read into
the canonical tables, checked and summarised.

A capture is described by a :class:`CaptureConfig` (the options of a ``kind: capture`` sequence in a datasets
file)::

    format: openpose                  # or coco (AlphaPose, MMPose/RTMPose results, COCO annotation files)
    views: [cam1/, cam2/, cam3/]      # one folder (openpose) or file (coco) per view, in view order
    image_size: [1920, 1080]          # [width, height] for every view, or one pair per view
    skeleton: body25                  # optional where the array length tells it (needed for 25 points)
    cameras: {path: calib.toml, format: pose2sim}   # optional known cameras, used instead of a calibration
                                      # (views: [cam2]: the file's cameras are those views'; refine: true)
    reference_cameras: {path: truth.toml}           # optional true cameras: evaluation only
    drop_views: [cam3]                # optional: views left out
    fps: 30                           # optional (default 30 where a frame rate is needed)
    view_fps: {cam2: 60}              # optional: per-view frame rates (the others: fps)
    unsynced: true                    # optional: the videos were started by hand (time offsets estimated)
    time_offsets: {cam2: 1.25}        # optional: seconds, view v's frame n is at n / fps_v + offset_v
    videos: [cam1.mp4, cam2/, ...]    # optional: the footage, one video file or image folder per view (overlays,
                                      # viewer; never used by the method)

Relative paths are relative to the datasets file's folder. Reading a capture checks what was declared against the
detections (:func:`load_capture`: image sizes, a 25-point skeleton, the views), then drops (and counts) joints
outside the image (negative or beyond the width/height: trackers extrapolate a few, no detector saw them) and
placeholder person entries without keypoints; every problem is a :class:`~humancal.formats.FormatError` or
``ValueError`` naming the file and the field, or the view and the option. Unsynchronised views (``unsynced``,
``time_offsets``, ``view_fps``) are moved to view 0's frames (:mod:`humancal.sync`) before the views are checked
against each other. Known cameras become the
``known_cameras`` table (the method uses them); reference cameras the ``gt_cameras`` table (evaluation only).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from humancal.capture_cameras import read_capture_cameras
from humancal.capture_options import (
    camera_file_option,
    is_size,
    named_numbers_option,
    parse_image_size,
    parse_principal_point,
    principal_points_option,
)
from humancal.formats import (
    CAMERA_READ_FORMATS,
    DETECTION_FORMATS,
    FormatError,
    read_detections,
)
from humancal.formats.detections import COCO_SKELETONS, OPENPOSE_SKELETONS, PLACEHOLDERS_ATTR
from humancal.formats.detections.checks import (
    check_image_sizes,
    check_view_paths,
    check_views,
    off_image,
)
from humancal.formats.detections.skeleton_fit import check_skeleton_fit
from humancal.formats.skeletons import SKELETONS
from humancal.tables import empty_table, validate_table

__all__ = ["OPTION_NAMES", "CaptureConfig", "CaptureSummary", "Capture", "load_capture", "view_name",
           "parse_image_size", "parse_principal_point", "principal_points_option"]

log = logging.getLogger(__name__)

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
        known_cameras: the views whose cameras are known (used by the method).
        reference_cameras: whether reference cameras come with it (evaluation only).
        total_frames: frames with a detection in any view.
        warnings: input that is probably wrong but usable, one line each (checks of ``load_capture``).
        sync: how unsynchronised views were put on view 0's clock (``humancal.sync.capture.CaptureSync``), or None
            (the views are in sync).
        footage: per view, its footage in words (kind, size, frames), or empty without footage.
    """

    names: tuple[str, ...]
    frames: tuple[int, ...]
    detections: tuple[int, ...]
    placeholders: tuple[int, ...]
    off_image_joints: tuple[int, ...]
    skeleton: str
    known_cameras: tuple[str, ...] = ()
    reference_cameras: bool = False
    total_frames: int = 0
    warnings: tuple[str, ...] = ()
    sync: Any = None
    footage: tuple[str, ...] = ()

    def lines(self) -> list[str]:
        """The summary in words, one line per view and a last line for the capture."""
        out = [
            f"  view {v} {name}: {f} frames with detections, {d} detections, {p} placeholder entries skipped, "
            f"{o} off-image joints dropped"
            for v, (name, f, d, p, o) in enumerate(
                zip(self.names, self.frames, self.detections, self.placeholders, self.off_image_joints)
            )
        ]
        if self.sync is not None:
            out = [f"{line}, {self.sync.view_text(v)}" for v, line in enumerate(out)]
        if self.footage:
            out = [f"{line}; footage: {footage}" for line, footage in zip(out, self.footage)]
        if len(self.known_cameras) == len(self.names):
            cams = "every camera known (used instead of a calibration)"
        elif self.known_cameras:
            cams = f"cameras of {', '.join(self.known_cameras)} known (the others calibrated around them)"
        else:
            cams = "cameras calibrated from the people"
        if self.reference_cameras:
            cams += "; reference cameras given (evaluation only)"
        out.append(f"  {len(self.names)} views, {self.total_frames} frames, {sum(self.detections)} detections, "
                   f"skeleton {self.skeleton}, {cams}")
        if self.sync is not None:
            out.append(f"  views put on one clock (the first view's frames), time offsets {self.sync.source}")
            unchecked = [n for n, st in zip(self.names, self.sync.status) if st == "unchecked"]
            if unchecked:
                out.append(f"  warning: the time offsets of {', '.join(unchecked)} rest on one pair of views only "
                           f"(not cross-checked by a third view)")
        return out + [f"  warning: {w}" for w in self.warnings]


@dataclass(frozen=True)
class Capture:
    """A capture's canonical tables and its summary.

    Attributes:
        detections: canonical ``detections`` table (on-image joints only).
        views: canonical ``views`` table.
        gt_cameras: canonical ``cameras`` table of the reference cameras (empty when none).
        summary: counts per view.
        known_cameras: canonical ``cameras`` table of the known cameras, the known views only (empty when none).
    """

    detections: pd.DataFrame
    views: pd.DataFrame
    gt_cameras: pd.DataFrame
    summary: CaptureSummary
    known_cameras: pd.DataFrame


def load_capture(config: CaptureConfig, sequence: str, *, option_names: Mapping[str, str] | None = None) -> Capture:
    """Read, check and summarise a capture.

    Checks, before anything is returned (``humancal.formats.detections.checks`` and ``.skeleton_fit`` state the
    rules): two views or more, each path once; each view's image size against where its joints lie; a 25-point
    skeleton against the people's anatomy (BODY_25 and BODY_25B); views with identical detections, without
    detections, or sharing no frame with the others. Joints outside the image are then dropped and counted.

    Args:
        config: where the files are.
        sequence: the sequence name written in every row.
        option_names: how messages name the options (keys of :data:`OPTION_NAMES`; missing keys keep its names).

    Returns:
        The capture's tables and summary (with the checks' warnings).

    Raises:
        FormatError: a bad detection or camera file (naming the file and field); known cameras that do not match
            the views (count, image size).
        FileNotFoundError: a folder or file does not exist.
        ValueError: no detection at all; an input check failed (``InputCheckError``, ``SkeletonMismatch``: the
            message names the view and the option to change).
    """
    names = {**OPTION_NAMES, **(option_names or {})}
    check_view_paths(config.views, names["views"])
    table = read_detections(list(config.views), config.format, sequence=sequence,
                            image_size=list(config.image_sizes_px), skeleton=config.skeleton)
    placeholders = dict(table.attrs.get(PLACEHOLDERS_ATTR, {}))
    sizes = dict(table.attrs.get("image_size_px", {}))
    if not len(table):
        raise FormatError(config.views[0], None, "at least one detected joint in the capture's files", "none")
    V = len(config.views)
    view_names = [view_name(p, v) for v, p in enumerate(config.views)]
    warnings = check_image_sizes(table, sizes, view_names, names["image_size"])
    footage = _check_footage(config, table, view_names, sizes, names["videos"]) if config.videos is not None else []
    warnings += [w for _, w in footage if w]
    skeleton = config.skeleton or table.attrs.get("skeleton")
    if skeleton is not None:
        family = OPENPOSE_SKELETONS if config.format == "openpose" else COCO_SKELETONS
        check_skeleton_fit(table, skeleton, [s for s in family if s != skeleton], names["skeleton"])
    width = table["view"].map(lambda v: sizes[v][0]).to_numpy(float)
    height = table["view"].map(lambda v: sizes[v][1]).to_numpy(float)
    off = off_image(table["x_px"].to_numpy(), table["y_px"].to_numpy(), width, height)
    off_per_view = table.loc[off, "view"].value_counts()
    if off.any():
        log.warning("%s: dropped %d joints outside the image (per view %s)", sequence, int(off.sum()),
                    off_per_view.to_dict())
    detections = table.loc[~off].reset_index(drop=True)
    sync = None
    if config.needs_sync:
        from humancal.sync.capture import synchronise_views

        detections, sync = synchronise_views(
            detections, view_names, fps=config.fps, view_fps=config.view_fps, unsynced=config.unsynced,
            time_offsets_s=config.time_offsets_s, option_names=names)
    warnings += check_views(detections, view_names, names["views"])
    views = validate_table(pd.DataFrame({
        "sequence": sequence, "view": np.arange(V), "name": view_names,
        "width_px": [sizes[v][0] for v in range(V)], "height_px": [sizes[v][1] for v in range(V)],
    }), "views")
    view_sizes = [tuple(sizes[v]) for v in range(V)]
    gt_cameras = (read_capture_cameras(config.reference_cameras, config.reference_cameras_format, sequence, view_names,
                                       view_sizes, format_option=names["reference_cameras_format"])
                  if config.reference_cameras is not None else empty_table("cameras"))
    known_cameras = (read_capture_cameras(config.cameras, config.cameras_format, sequence, view_names, view_sizes,
                                          views=config.known_views, format_option=names["cameras_format"],
                                          views_option=names["known_views"])
                     if config.cameras is not None else empty_table("cameras"))
    per_view = detections.groupby("view")
    dets = per_view.apply(lambda g: g.groupby(["frame", "det_id"]).ngroups, include_groups=False)
    frames = per_view["frame"].nunique()
    summary = CaptureSummary(
        names=tuple(view_names),
        frames=tuple(int(frames.get(v, 0)) for v in range(V)),
        detections=tuple(int(dets.get(v, 0)) for v in range(V)),
        placeholders=tuple(int(placeholders.get(v, 0)) for v in range(V)),
        off_image_joints=tuple(int(off_per_view.get(v, 0)) for v in range(V)),
        skeleton=config.skeleton or f"{table.attrs.get('skeleton') or 'unknown'} (told from the array length)",
        known_cameras=tuple(view_names[int(v)] for v in sorted(known_cameras["view"])),
        reference_cameras=config.reference_cameras is not None,
        total_frames=int(detections["frame"].nunique()),
        warnings=tuple(warnings),
        sync=sync,
        footage=tuple(text for text, _ in footage),
    )
    capture = Capture(detections=detections, views=views, gt_cameras=gt_cameras, summary=summary,
                      known_cameras=known_cameras)
    return _drop_views(capture, config.drop_views, names["drop_views"]) if config.drop_views else capture


def _drop_views(capture: Capture, drop: tuple[str, ...], option: str) -> Capture:
    """The capture without the views named in ``drop`` (the rest numbered again in order).

    Raises:
        ValueError: a name that is no view, or fewer than two views left.
    """
    names = list(capture.summary.names)
    unknown = [n for n in drop if n not in names]
    if unknown:
        raise ValueError(f"{option}: {unknown} are not views of the capture (its views: {names})")
    keep = [v for v, n in enumerate(names) if n not in drop]
    if len(keep) < 2:
        raise ValueError(f"{option}: {len(keep)} view(s) left; a capture needs two views or more")
    number = {old: new for new, old in enumerate(keep)}

    def renumber(table: pd.DataFrame) -> pd.DataFrame:
        kept = table[table["view"].isin(keep)].copy()
        kept["view"] = kept["view"].map(number).astype(table["view"].dtype)
        return kept.reset_index(drop=True)

    summary = capture.summary
    pick = lambda values: tuple(values[v] for v in keep)  # noqa: E731
    summary = dataclasses.replace(
        summary, names=pick(summary.names), frames=pick(summary.frames), detections=pick(summary.detections),
        placeholders=pick(summary.placeholders), off_image_joints=pick(summary.off_image_joints),
        known_cameras=tuple(n for n in summary.known_cameras if n not in drop),
        sync=summary.sync.pick(keep) if summary.sync is not None else None,
        footage=pick(summary.footage) if summary.footage else (),
        warnings=summary.warnings + (f"views {list(drop)} left out ({option})",))
    return Capture(renumber(capture.detections), renumber(capture.views), renumber(capture.gt_cameras), summary,
                   renumber(capture.known_cameras))


def _check_footage(config: CaptureConfig, table: pd.DataFrame, view_names: list[str], sizes: Mapping[int, Any],
                   option: str) -> list[tuple[str, str]]:
    """Per view: its footage in words and a warning (or ""), after :func:`humancal.viewing.footage.check_footage`
    against the view's image size and its detections' last frame (its own frame numbers)."""
    from humancal.viewing.footage import check_footage, open_footage

    last = table.groupby("view")["frame"].max()
    out = []
    for v, (name, path) in enumerate(zip(view_names, config.videos or ())):
        try:
            footage = open_footage(path)
        except FileNotFoundError as err:
            raise FileNotFoundError(f"{option}: view {name}: {err}") from None
        warnings = check_footage(footage, name, tuple(sizes[v]), int(last.get(v, -1)), option)
        out.append((f"{footage.kind} {footage.size_px[0]}x{footage.size_px[1]}, {footage.num_frames} frames",
                    "; ".join(warnings)))
    return out


def view_name(path: Path, view: int) -> str:
    """A view's name: its detection folder's name, or its file's stem (``view_<v>`` when empty)."""
    name = path.name if path.is_dir() else path.stem
    return name or f"view_{view}"
