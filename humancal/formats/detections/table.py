"""The canonical ``detections`` table from per-image keypoint arrays, and back.

The table (``humancal.tables.schemas.SCHEMAS["detections"]``) has one row per *present* canonical joint of a detection:
sequence, frame, view, det_id, joint, x_px, y_px, score. Readers build it with :func:`detections_from_arrays`;
writers go the other way with :func:`detections_to_arrays`.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from humancal.formats.errors import FormatError
from humancal.keypoints import CANONICAL_JOINTS, JOINT_INDEX, NUM_JOINTS
from humancal.tables.detections import detections_to_dense
from humancal.tables.schemas import empty_table, validate_table

__all__ = [
    "IMAGE_SIZE_ATTR",
    "PLACEHOLDERS_ATTR",
    "SKELETON_ATTR",
    "ImageArrays",
    "detections_from_arrays",
    "detections_to_arrays",
    "sort_detections",
    "image_sizes_by_view",
]

logger = logging.getLogger(__name__)

IMAGE_SIZE_ATTR = "image_size_px"
"""Key of ``DataFrame.attrs`` under which readers leave ``{view: (width_px, height_px)}``."""

PLACEHOLDERS_ATTR = "skipped_placeholders"
"""Key of ``DataFrame.attrs`` under which readers leave ``{view: number of person entries skipped}`` (entries with
an empty keypoint list, which some trackers write as placeholders)."""

SKELETON_ATTR = "skeleton"
"""Key of ``DataFrame.attrs`` under which readers leave the name of the skeleton they read (``None``: no people)."""

ImageArrays = tuple[np.ndarray, np.ndarray, np.ndarray]
"""(det_ids (P,), keypoints (P, 23, 2) pixels with NaN where absent, scores (P, 23) with 0 where absent)."""


def detections_from_arrays(
    images: Sequence[tuple[int, int, np.ndarray, np.ndarray]],
    sequence: str,
    *,
    source: str = "",
) -> pd.DataFrame:
    """The canonical detections table of per-image canonical keypoints.

    Args:
        images: (frame, view, keypoints (P, 23, 2) pixels, scores (P, 23)) per image; the det_id of a detection is its
            index P in its image. Joints with score <= 0 or non-finite coordinates have no row. Scores above 1 (heatmap
            peaks of some detectors reach 1.05) are clipped to 1, and the count is logged as a warning.
        sequence: the sequence name of every row.
        source: what the rows were read from, for error messages.

    Returns:
        The validated table, sorted by frame, view, det_id and canonical joint order.
    """
    parts = []
    names = np.array(CANONICAL_JOINTS, dtype=object)
    clipped = 0
    for frame, view, keypoints, scores in images:
        kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, NUM_JOINTS, 2)
        sc = np.asarray(scores, dtype=np.float64).reshape(-1, NUM_JOINTS)
        with np.errstate(invalid="ignore"):
            det, joint = np.nonzero((sc > 0) & np.isfinite(kp).all(axis=-1))
        if not len(det):
            continue
        score = sc[det, joint]
        clipped += int((score > 1.0).sum())
        parts.append(
            pd.DataFrame(
                {
                    "sequence": sequence,
                    "frame": int(frame),
                    "view": int(view),
                    "det_id": det,
                    "joint": names[joint],
                    "x_px": kp[det, joint, 0],
                    "y_px": kp[det, joint, 1],
                    "score": np.minimum(score, 1.0),
                }
            )
        )
    if clipped:
        logger.warning("%s: %d joint score(s) above 1 clipped to 1", source or "detections", clipped)
    if not parts:
        return empty_table("detections")
    return sort_detections(validate_table(pd.concat(parts, ignore_index=True), "detections", source=source))


def sort_detections(detections: pd.DataFrame) -> pd.DataFrame:
    """``detections`` sorted by frame, view, det_id and canonical joint order, with a fresh 0..N-1 index."""
    order = detections["joint"].map(JOINT_INDEX)
    return (
        detections.assign(_joint_order=order)
        .sort_values(["sequence", "frame", "view", "det_id", "_joint_order"], kind="stable")
        .drop(columns="_joint_order")
        .reset_index(drop=True)
    )


def detections_to_arrays(detections: pd.DataFrame, *, source: str = "") -> dict[tuple[int, int], ImageArrays]:
    """Per image, the canonical keypoint arrays of a detections table.

    Args:
        detections: a canonical detections table (validated here).
        source: what the table is, for error messages.

    Returns:
        ``{(frame, view): (det_ids (P,), keypoints (P, 23, 2), scores (P, 23))}`` with det_ids ascending; only images
        that have rows appear.

    Raises:
        TableError: the table does not match its schema.
        FormatError: a joint name is not canonical, or a (frame, view, det_id, joint) appears twice.
    """
    table = validate_table(detections, "detections", source=source)
    if not len(table):
        return {}
    try:
        dense = detections_to_dense(table)
    except ValueError as err:  # a non-canonical joint name or a repeated (frame, view, det_id, joint)
        raise FormatError(source or None, "joint", f"canonical joint names {list(CANONICAL_JOINTS)}, each "
                          "(frame, view, det_id, joint) at most once", str(err)) from err
    uniq = np.stack([dense.frame, dense.view, dense.det_id], axis=1)
    kp, sc = dense.keypoints_px, dense.scores
    out: dict[tuple[int, int], ImageArrays] = {}
    image_keys = uniq[:, :2]
    starts = np.flatnonzero(np.r_[True, (image_keys[1:] != image_keys[:-1]).any(axis=1)])
    ends = np.r_[starts[1:], len(uniq)]
    for s, e in zip(starts, ends):
        out[(int(uniq[s, 0]), int(uniq[s, 1]))] = (uniq[s:e, 2].copy(), kp[s:e], sc[s:e])
    return out


def image_sizes_by_view(
    image_size: tuple[int, int] | Sequence[tuple[int, int]] | Mapping[int, tuple[int, int]] | None,
    views: Sequence[int],
) -> dict[int, tuple[int, int]] | None:
    """``image_size`` argument as ``{view: (width_px, height_px)}``.

    Accepts one (width, height) pair for every view, a sequence of pairs in view order, or a mapping by view.

    Raises:
        ValueError: a size is not two positive integers, or a view has none.
    """
    if image_size is None:
        return None
    if isinstance(image_size, Mapping):
        sizes = {int(v): image_size[v] for v in image_size}
    elif len(image_size) == 2 and all(np.isscalar(x) for x in image_size):
        sizes = {v: image_size for v in views}
    else:
        if len(image_size) != len(views):
            raise ValueError(
                f"image_size: expected one (width_px, height_px) per view ({len(views)}), got {len(image_size)}"
            )
        sizes = dict(zip(views, image_size))
    out = {}
    for v in views:
        if v not in sizes:
            raise ValueError(f"image_size: no (width_px, height_px) for view {v}; given for views {sorted(sizes)}")
        out[v] = _size_pair(sizes[v], f"image_size of view {v}")
    return out


def _size_pair(value: object, what: str) -> tuple[int, int]:
    try:
        w, h = (float(x) for x in value)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected (width_px, height_px), got {value!r}") from None
    if not (w > 0 and h > 0 and w == int(w) and h == int(h)):
        raise ValueError(f"{what}: expected two positive integers (width_px, height_px), got {value!r}")
    return int(w), int(h)
