"""Which of two same-length skeletons a set of detections follows, told by the people's anatomy.

OpenPose's BODY_25 and BODY_25B both have 25 points, in different orders, so a file cannot say which one wrote it.
Read with the wrong one, the canonical joints land on other body parts: BODY_25B read as BODY_25 puts the eyes on
the ankles and the ankles on a knee and a hip; BODY_25 read as BODY_25B puts the ankles on the eyes and the left
eye on the neck. The joints that are close neighbours on any body then lie far apart.

The statistic (:func:`neighbour_spread`): for every detection and every pair of :data:`NEIGHBOUR_PAIRS` (nose-eye,
eye-ear, ankle-heel, ankle-big toe) present in it, the pair's distance divided by the diagonal of the detection's
bounding box (all its joints, in pixels); the median over all of them. The bounding box is the same under every
reading (the same points, differently named), so the readings compare fairly. Measured on the synthetic demo and
on Shelf's real OpenPose detections: 0.04 read with the right skeleton, 0.3-0.86 with the wrong one.

The rule (:func:`check_skeleton_fit`): the declared skeleton fits when its median is at most
:data:`FIT_SPREAD` (0.15). When it does not and another skeleton of the same length fits with at most half its
median, the declared skeleton is wrong and the error names the other one. Fewer than :data:`MIN_PAIRS` measured
pairs (captures without faces and feet) decide nothing.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
import pandas as pd

from humancal.formats.skeletons import SKELETONS, get_skeleton
from humancal.keypoints import JOINT_INDEX
from humancal.tables.detections import detections_to_dense

__all__ = ["FIT_SPREAD", "MIN_PAIRS", "NEIGHBOUR_PAIRS", "SkeletonMismatch", "check_skeleton_fit",
           "neighbour_spread", "reinterpret"]

log = logging.getLogger(__name__)

NEIGHBOUR_PAIRS: tuple[tuple[str, str], ...] = (
    ("nose", "left_eye"), ("nose", "right_eye"), ("left_eye", "left_ear"), ("right_eye", "right_ear"),
    ("left_ankle", "left_heel"), ("right_ankle", "right_heel"),
    ("left_ankle", "left_big_toe"), ("right_ankle", "right_big_toe"),
)  # fmt: skip
"""Canonical joints that are close neighbours on every body (a few percent of its size apart)."""

FIT_SPREAD = 0.15
"""Largest median neighbour distance, as a fraction of the person's bounding-box diagonal, of a fitting skeleton."""

MIN_PAIRS = 30
"""Fewest measured neighbour pairs for a verdict."""


class SkeletonMismatch(ValueError):
    """The detections fit another skeleton than the declared one (the message names both)."""


def reinterpret(keypoints_px: np.ndarray, declared: str, other: str) -> np.ndarray:
    """Canonical keypoints as they would have been read with ``other`` instead of ``declared``.

    A raw array index ``i`` was read as the canonical joint ``declared.joints[i]``; read with ``other`` it is
    ``other.joints[i]``. Joints that one of the two skeletons does not map to the canonical set come out absent.

    Args:
        keypoints_px: (..., 23, 2) canonical keypoints read with ``declared`` (NaN where absent).
        declared, other: skeleton names with the same number of joints.

    Returns:
        (..., 23, 2) the same points under ``other``'s joint names (NaN where absent).
    """
    d, o = get_skeleton(declared), get_skeleton(other)
    if d.num_joints != o.num_joints:
        raise ValueError(f"skeletons '{d.name}' ({d.num_joints} joints) and '{o.name}' ({o.num_joints}) differ in "
                         "length")
    out = np.full_like(np.asarray(keypoints_px, dtype=np.float64), np.nan)
    for i, name in enumerate(d.joints):
        if name in JOINT_INDEX and o.joints[i] in JOINT_INDEX:
            out[..., JOINT_INDEX[o.joints[i]], :] = keypoints_px[..., JOINT_INDEX[name], :]
    return out


def neighbour_spread(keypoints_px: np.ndarray, declared: str, other: str | None = None) -> tuple[float, int]:
    """The median distance between neighbour joints, as a fraction of each person's size (module docstring).

    Args:
        keypoints_px: (D, 23, 2) canonical keypoints of D detections read with ``declared`` (NaN where absent).
        declared: the skeleton they were read with.
        other: measure them as read with this skeleton instead (``None``: as read).

    Returns:
        (median fraction, number of measured pairs); (nan, 0) when no pair is measured.
    """
    size = _box_diagonals_px(keypoints_px)
    kp = keypoints_px if other is None else reinterpret(keypoints_px, declared, other)
    ratios = []
    for a, b in NEIGHBOUR_PAIRS:
        d = np.linalg.norm(kp[:, JOINT_INDEX[a]] - kp[:, JOINT_INDEX[b]], axis=-1)
        ok = np.isfinite(d) & (size > 0)
        ratios.append(d[ok] / size[ok])
    r = np.concatenate(ratios)
    return (float(np.median(r)), len(r)) if len(r) else (float("nan"), 0)


def _box_diagonals_px(keypoints_px: np.ndarray) -> np.ndarray:
    """(D,) bounding-box diagonal of each detection's present joints (D, 23, 2), pixels (0 for one joint)."""
    present = np.isfinite(keypoints_px).all(axis=-1)
    lo = np.where(present[..., None], keypoints_px, np.inf).min(axis=1)
    hi = np.where(present[..., None], keypoints_px, -np.inf).max(axis=1)
    with np.errstate(invalid="ignore"):
        diag = np.linalg.norm(hi - lo, axis=-1)
    return np.where(np.isfinite(diag), diag, 0.0)


def check_skeleton_fit(detections: pd.DataFrame, declared: str, candidates: Sequence[str] | None = None,
                       option: str = "skeleton") -> None:
    """Raise when the detections fit another skeleton of the same length better than the declared one.

    Args:
        detections: canonical detections table read with ``declared``.
        declared: the skeleton name the files were read with.
        candidates: the other skeletons the files could hold (default: every registered skeleton with as many
            joints as ``declared``).
        option: how the caller names the skeleton option in messages (``--skeleton`` on the command line).

    Raises:
        SkeletonMismatch: the declared skeleton's median neighbour spread is above :data:`FIT_SPREAD` and a
            candidate's is at most :data:`FIT_SPREAD` and at most half of it; the message names the candidate.
    """
    declared = get_skeleton(declared).name
    length = get_skeleton(declared).num_joints
    if candidates is None:
        candidates = [name for name, s in SKELETONS.items() if s.num_joints == length and name != declared]
    candidates = [c for c in candidates if c != declared and get_skeleton(c).num_joints == length]
    if not candidates or not len(detections):
        return
    keypoints = detections_to_dense(detections).keypoints_px
    spread, pairs = neighbour_spread(keypoints, declared)
    if pairs < MIN_PAIRS or spread <= FIT_SPREAD:
        return
    others = {c: neighbour_spread(keypoints, declared, c) for c in candidates}
    fitting = {c: s for c, (s, n) in others.items() if n >= MIN_PAIRS and s <= FIT_SPREAD and s <= spread / 2}
    if not fitting:
        log.warning("the detections fit no %d-point skeleton well (median distance between neighbour joints %.0f %% "
                    "of a person's size as %s)", length, 100 * spread, declared)
        return
    best = min(fitting, key=fitting.get)
    raise SkeletonMismatch(
        f"the {length}-point detections do not look like {declared}: joints that are neighbours on a body (nose and "
        f"eyes, eyes and ears, ankles and heels and big toes) lie a median {100 * spread:.0f} % of the person's size "
        f"apart, {100 * fitting[best]:.0f} % when read as {best}: is the skeleton {best} ({option})?"
    )
