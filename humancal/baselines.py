"""Reference reconstructions that use information the method must do without.

``triangulate_identified``: given cameras and the identity of every detection, triangulate each
person's canonical keypoints frame by frame (confidence-weighted DLT, one outlier pass). With the
ground-truth cameras and identities this is the `gt_camera_triangulation` row of every metric table:
the floor that self-calibration is compared against.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.camera import CameraRig
from humancal.config import Config, at_least, in_range, positive
from humancal.geometry.triangulation import triangulate_dlt
from humancal.keypoints import CANONICAL_JOINTS, NUM_JOINTS
from humancal.tables.associations import Associations
from humancal.tables.detections import detections_to_dense
from humancal.tables.pivot import has_repeats, unique_rows
from humancal.tables.schemas import empty_table, validate_table

__all__ = ["TriangulationConfig", "triangulate_identified"]


@dataclass(frozen=True)
class TriangulationConfig(Config):
    """Settings of the identified-detections triangulation.

    Attributes:
        min_score: observations with a lower confidence are ignored.
        min_views: a joint needs this many views.
        outlier_threshold_px: views reprojecting farther than this (pixels) from the first solution
            are dropped for that joint and the joint is solved again (None disables the pass).
    """

    min_score: float = field(default=0.1, metadata=in_range(0, 1))
    min_views: int = field(default=2, metadata=at_least(2, integer=True))
    outlier_threshold_px: float | None = field(default=40.0, metadata=positive(optional=True))


def triangulate_identified(
    detections: pd.DataFrame,
    associations: pd.DataFrame,
    cameras: CameraRig,
    sequence: str,
    config: TriangulationConfig = TriangulationConfig(),
) -> pd.DataFrame:
    """Triangulate every identified person in every frame.

    Args:
        detections: canonical ``detections`` table.
        associations: canonical ``associations`` table (person_id -1 = not a person: skipped).
        cameras: the rig, one camera per view.
        sequence: value of the ``sequence`` column of the output.
        config: thresholds.

    Returns:
        Canonical ``poses3d`` table (world metres), one row per (frame, person_id, joint) with at least
        one observation; ``valid`` is False (and coordinates NaN) where fewer than ``min_views`` views
        saw the joint.

    Raises:
        ValueError: a detection refers to a view without a camera, or one person has two detections
            in the same view and frame.
    """
    dense = detections_to_dense(detections)
    n_views = len(cameras)
    if len(dense) and dense.view.max() >= n_views:
        raise ValueError(f"detections use view {int(dense.view.max())} but only {n_views} cameras were given")
    person = Associations.from_table(associations).person_of_detections(dense)
    keep = person >= 0
    frame, view, person = dense.frame[keep], dense.view[keep], person[keep]
    kp, sc = dense.keypoints_px[keep], dense.scores[keep]
    if len(frame) == 0:
        return empty_table("poses3d")

    pairs, slot = unique_rows(np.stack([frame, person], 1))
    flat_key = slot * n_views + view
    if has_repeats(flat_key, len(pairs) * n_views):
        raise ValueError("associations give one person two detections in the same view and frame")
    S = len(pairs)
    points = np.full((n_views, S, NUM_JOINTS, 2), np.nan)
    weights = np.zeros((n_views, S, NUM_JOINTS))
    points[view, slot] = kp
    weights[view, slot] = np.where(sc >= config.min_score, sc, 0.0)

    X, used = triangulate_dlt(
        cameras,
        points.reshape(n_views, S * NUM_JOINTS, 2),
        weights.reshape(n_views, S * NUM_JOINTS),
        min_views=config.min_views,
        outlier_threshold_px=config.outlier_threshold_px,
    )
    X = X.reshape(S, NUM_JOINTS, 3)
    observed = (weights > 0).any(0)  # (S, J)
    s_idx, j_idx = np.nonzero(observed)
    out = pd.DataFrame(
        {
            "sequence": sequence,
            "frame": pairs[s_idx, 0],
            "person_id": pairs[s_idx, 1],
            "joint": np.asarray(CANONICAL_JOINTS)[j_idx],
            "x_m": X[s_idx, j_idx, 0],
            "y_m": X[s_idx, j_idx, 1],
            "z_m": X[s_idx, j_idx, 2],
            "valid": used.reshape(S, NUM_JOINTS)[s_idx, j_idx] >= config.min_views,
        }
    )
    return validate_table(out, "poses3d")
