"""Reading a capture (:func:`load_capture`): its detections into the canonical tables, checked against what was
declared and summarised per view (``humancal.captures`` describes the checks)."""


from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from humancal.captures.cameras import read_capture_cameras
from humancal.captures.config import OPTION_NAMES, CaptureConfig
from humancal.formats import FormatError, read_detections
from humancal.formats.detections import COCO_SKELETONS, OPENPOSE_SKELETONS, PLACEHOLDERS_ATTR
from humancal.formats.detections.checks import (
    check_image_sizes,
    check_view_paths,
    check_views,
    off_image,
)
from humancal.formats.detections.skeleton_fit import check_skeleton_fit
from humancal.tables.schemas import empty_table, validate_table

__all__ = ["Capture", "CaptureSummary", "load_capture", "view_name"]

log = logging.getLogger(__name__)

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
    off = off_image(table["x_px"].to_numpy(), table["y_px"].to_numpy(),
                    *(table["view"].map(lambda v, i=i: sizes[v][i]).to_numpy(float) for i in (0, 1)))
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
            time_offsets_s=config.time_offsets_s, option_names=names,
            image_sizes_px=[tuple(sizes[v]) for v in range(len(config.views))])
    warnings += check_views(detections, view_names, names["views"])
    views = validate_table(pd.DataFrame({
        "sequence": sequence, "view": np.arange(V), "name": view_names,
        "width_px": [sizes[v][0] for v in range(V)], "height_px": [sizes[v][1] for v in range(V)],
    }), "views")
    gt_cameras, known_cameras = _capture_cameras(config, sequence, view_names, [tuple(sizes[v]) for v in range(V)],
                                                 names)
    frames = detections.groupby("view")["frame"].nunique()
    dets = detections.groupby("view").apply(lambda g: g.groupby(["frame", "det_id"]).ngroups, include_groups=False)
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


def _capture_cameras(config: CaptureConfig, sequence: str, view_names: list[str], view_sizes: list[tuple],
                     names: Mapping[str, str]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The ``cameras`` tables of the reference cameras (evaluation only) and of the known ones (the known views
    only); empty where the capture has none."""
    gt_cameras = (read_capture_cameras(config.reference_cameras, config.reference_cameras_format, sequence, view_names,
                                       view_sizes, format_option=names["reference_cameras_format"])
                  if config.reference_cameras is not None else empty_table("cameras"))
    known_cameras = (read_capture_cameras(config.cameras, config.cameras_format, sequence, view_names, view_sizes,
                                          views=config.known_views, format_option=names["cameras_format"],
                                          views_option=names["known_views"])
                     if config.cameras is not None else empty_table("cameras"))
    return gt_cameras, known_cameras


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
