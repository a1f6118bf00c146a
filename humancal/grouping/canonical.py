"""Grouped BODY_25 people to the canonical 23 joints (:func:`humancal.formats.to_canonical`) and the canonical
``detections`` table."""

from __future__ import annotations

import logging
from collections.abc import Iterable

import numpy as np
import pandas as pd

from humancal.formats.detections.table import sort_detections
from humancal.formats.joint_mapping import to_canonical
from humancal.grouping.candidates import CandidateFrame
from humancal.grouping.greedy import GroupedPeople, GroupingConfig, group_frame
from humancal.keypoints import CANONICAL_JOINTS
from humancal.tables.schemas import empty_table, validate_table

__all__ = ["group_detections", "people_to_detections"]

logger = logging.getLogger(__name__)


def group_detections(
    images: Iterable[tuple[int, int, CandidateFrame]], sequence: str, config: GroupingConfig | None = None
) -> pd.DataFrame:
    """Group the BODY_25 candidates of many images into people: the canonical ``detections`` table.

    Args:
        images: (frame, view, candidates) per image.
        sequence: sequence name of every row.
        config: grouping thresholds; defaults to :class:`~humancal.grouping.GroupingConfig`.

    Returns:
        See :func:`people_to_detections`.
    """
    config = config or GroupingConfig()
    return people_to_detections(((f, v, group_frame(c, config)) for f, v, c in images), sequence)


def people_to_detections(people: Iterable[tuple[int, int, GroupedPeople]], sequence: str) -> pd.DataFrame:
    """The canonical ``detections`` table of grouped BODY_25 people.

    Args:
        people: (frame, view, people) per image; the det_id of a person is its index within its image.
        sequence: sequence name of every row.

    Returns:
        One row per detected canonical joint (joints without a candidate have no row; neck and mid-hip are not
        canonical), confidence = candidate score, sorted by frame, view, det_id and canonical joint order. Scores
        above 1 (OpenPose heatmap peaks reach 1.04 on Shelf) are clipped to 1 and counted in a warning.
    """
    frames, views, dets, joints, xs, ys, scores = [], [], [], [], [], [], []
    for frame, view, grouped in people:
        xy, score = to_canonical(grouped.xy_px, grouped.score, "body25")
        det, joint = np.nonzero(score > 0)
        frames.append(np.full(len(det), frame))
        views.append(np.full(len(det), view))
        dets.append(det)
        joints.append(joint)
        xs.append(xy[det, joint, 0])
        ys.append(xy[det, joint, 1])
        scores.append(score[det, joint])
    if not frames or not sum(len(d) for d in dets):
        return empty_table("detections")
    score = np.concatenate(scores)
    clipped = int((score > 1.0).sum())
    if clipped:
        logger.warning("grouped detections of '%s': %d joint score(s) above 1 clipped to 1", sequence, clipped)
    table = pd.DataFrame(
        {
            "sequence": sequence,
            "frame": np.concatenate(frames),
            "view": np.concatenate(views),
            "det_id": np.concatenate(dets),
            "joint": np.array(CANONICAL_JOINTS, dtype=object)[np.concatenate(joints)],
            "x_px": np.concatenate(xs),
            "y_px": np.concatenate(ys),
            "score": np.minimum(score, 1.0),
        }
    )
    return sort_detections(validate_table(table, "detections", source=f"grouped detections of '{sequence}'"))
