"""2D detections from detector files into the canonical ``detections`` table, and back out.

``read_detections`` dispatches on ``format``:

``"openpose"``
    one OpenPose JSON folder per view (:mod:`humancal.formats.detections.openpose`); BODY_25, BODY_25B (named:
    both have 25 points) or COCO-18.
``"coco"``
    one COCO-style keypoint JSON file per view (:mod:`humancal.formats.detections.coco`); COCO-17, Halpe-26 or
    COCO-WholeBody.

The returned table carries the image size of every view in ``table.attrs["image_size_px"]``
(``{view: (width_px, height_px)}``), taken from the files when they have it, else from the ``image_size`` argument,
which is then required, and the number of placeholder person entries (empty keypoint lists) skipped per view in
``table.attrs["skipped_placeholders"]``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from humancal.formats.detections.coco import COCO_SKELETONS, read_coco_keypoints
from humancal.formats.detections.openpose import OPENPOSE_SKELETONS, read_openpose, write_openpose
from humancal.formats.detections.table import (
    IMAGE_SIZE_ATTR,
    PLACEHOLDERS_ATTR,
    SKELETON_ATTR,
    detections_from_arrays,
    detections_to_arrays,
    image_sizes_by_view,
    sort_detections,
)
from humancal.formats.errors import FormatError
from humancal.formats.skeletons import Skeleton, get_skeleton
from humancal.tables.schemas import empty_table

__all__ = [
    "DETECTION_FORMATS",
    "IMAGE_SIZE_ATTR",
    "PLACEHOLDERS_ATTR",
    "COCO_SKELETONS",
    "OPENPOSE_SKELETONS",
    "read_detections",
    "read_openpose",
    "write_openpose",
    "read_coco_keypoints",
    "detections_from_arrays",
    "detections_to_arrays",
    "sort_detections",
]

DETECTION_FORMATS = ("openpose", "coco")
"""Formats ``read_detections`` understands."""

ImageSize = tuple[int, int] | Sequence[tuple[int, int]] | Mapping[int, tuple[int, int]]


def read_detections(
    paths_by_view: Sequence[str | Path] | Mapping[int, str | Path],
    format: str,
    *,
    sequence: str,
    image_size: ImageSize | None = None,
    skeleton: str | Skeleton | None = None,
    frame_from: str = "auto",
) -> pd.DataFrame:
    """Read 2D detections of every view into the canonical detections table.

    Args:
        paths_by_view: per view, an OpenPose folder (``"openpose"``) or a JSON file (``"coco"``); a sequence gives
            views 0..V-1 in order, a mapping gives view numbers explicitly.
        format: one of :data:`DETECTION_FORMATS`.
        sequence: sequence name written in every row.
        image_size: (width_px, height_px) for every view, one pair per view (sequence in view order or mapping by
            view). Required when the files do not carry the size (OpenPose, COCO results lists); when both exist
            they must agree.
        skeleton: the files' skeleton (``None``: inferred from the array length, an error when two skeletons have
            that length, as BODY_25 and BODY_25B do).
        frame_from: how frame numbers are found: ``"auto"``, ``"name_number"`` (the number in the file or image
            name), ``"name_order"`` (the rank of the name in sorted order), or for ``"coco"`` also ``"image_id"``
            (integer image ids are the frames); see the format's module.

    Returns:
        The canonical detections table, sorted by frame, view, det_id and joint, with
        ``attrs["image_size_px"] = {view: (width_px, height_px)}`` and ``attrs["skipped_placeholders"] =
        {view: count}``.

    Raises:
        FormatError: unknown format (the message lists the known ones), a bad file, a missing or contradicting
            image size.
        FileNotFoundError: a folder or file does not exist.
    """
    if format not in DETECTION_FORMATS:
        raise FormatError(None, "format", f"one of {list(DETECTION_FORMATS)}", repr(format))
    items = paths_by_view.items() if isinstance(paths_by_view, Mapping) else enumerate(paths_by_view)
    paths = dict(sorted((int(v), Path(p)) for v, p in items))
    if not paths:
        raise ValueError("paths_by_view: expected at least one view, got none")
    given = image_sizes_by_view(image_size, list(paths))
    if format == "openpose" and given is None:
        expected = "image_size=(width_px, height_px) (OpenPose JSON does not carry it)"
        raise FormatError(paths[min(paths)], "image size", expected, "none")
    if format == "openpose":
        table = read_openpose(paths, sequence=sequence, skeleton=skeleton, frame_from=frame_from)
        from_files: dict[int, tuple[int, int]] = {}
        placeholders = dict(table.attrs.get(PLACEHOLDERS_ATTR, {}))
    else:
        parts, from_files, placeholders = [], {}, {}
        for v, path in paths.items():
            part, size = read_coco_keypoints(
                path, view=v, sequence=sequence, skeleton=skeleton, frame_from=frame_from
            )
            parts.append(part)
            placeholders[v] = part.attrs.get(PLACEHOLDERS_ATTR, {}).get(v, 0)
            skeleton = part.attrs.get(SKELETON_ATTR) or skeleton
            if size is not None:
                from_files[v] = size
        non_empty = [p for p in parts if len(p)]
        table = sort_detections(pd.concat(non_empty, ignore_index=True)) if non_empty else empty_table("detections")
    sizes = {}
    for v, path in paths.items():
        if v in from_files:
            if given is not None and given[v] != from_files[v]:
                expected = f"the image_size argument {given[v]}"
                raise FormatError(path, "image size", expected, f"{from_files[v]} in the file")
            sizes[v] = from_files[v]
        elif given is not None:
            sizes[v] = given[v]
        else:
            expected = f"image_size=(width_px, height_px) (the {format} file(s) of view {v} do not carry it)"
            raise FormatError(path, "image size", expected, "none")
    table.attrs[IMAGE_SIZE_ATTR] = sizes
    table.attrs[PLACEHOLDERS_ATTR] = placeholders
    if format == "coco":
        table.attrs[SKELETON_ATTR] = None if skeleton is None else get_skeleton(skeleton).name
    return table
