"""Checks shared by the detection readers: which skeleton a flat keypoint array holds, and its values."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from humancal.formats.errors import FormatError
from humancal.formats.skeletons import Skeleton, get_skeleton

__all__ = ["skeleton_of_length", "checked_keypoints"]


def skeleton_of_length(
    length: int, given: Skeleton | None, candidates: tuple[str, ...], path: Path, field: str
) -> Skeleton:
    """The skeleton of a flat [x, y, score] * J array of ``length`` numbers.

    Args:
        length: number of values in the array.
        given: the skeleton the caller expects (from the argument, or inferred from an earlier array); the length
            must match it.
        candidates: skeleton names told apart by length when ``given`` is None; a length that fits several is
            an error (never a guess).
        path, field: where the array comes from, for the message.

    Raises:
        FormatError: the length does not match ``given``, fits no candidate, or fits several.
    """
    if given is not None:
        if length != 3 * given.num_joints:
            expected = f"{3 * given.num_joints} numbers ({given.num_joints} joints of '{given.name}' x 3)"
            raise FormatError(path, field, expected, f"{length} numbers")
        return given
    fits = [name for name in candidates if length == 3 * get_skeleton(name).num_joints]
    if len(fits) > 1:
        # BODY_25 and BODY_25B both have 25 points in different orders: guessing would silently swap joints.
        names = " and ".join(repr(f) for f in fits)
        expected = f"a named skeleton (skeleton=, on the command line --skeleton): {length} numbers fit {names}"
        raise FormatError(path, field, expected, "none")
    if fits:
        return get_skeleton(fits[0])
    counts = ", ".join(f"{3 * get_skeleton(n).num_joints} ({n})" for n in candidates)
    raise FormatError(path, field, f"{counts} numbers", f"{length} numbers")


def checked_keypoints(values: list, skel: Skeleton, path: Path, field: str, score_name: str = "score") -> np.ndarray:
    """A flat [x, y, score] * J list as a (J, 3) array, checked.

    Checks: numbers only (no strings, booleans or nulls); every score finite and >= 0; finite coordinates wherever
    the score is positive (a joint with score 0 is absent, its coordinates are not looked at).

    Raises:
        FormatError: naming the joint by index and name.
    """
    bad = next((x for x in values if not isinstance(x, (int, float)) or isinstance(x, bool)), _NONE)
    if bad is not _NONE:
        raise FormatError(path, field, "numbers only", repr(bad))
    arr = np.asarray(values, dtype=np.float64).reshape(skel.num_joints, 3)
    score = arr[:, 2]
    bad_score = ~np.isfinite(score) | (score < 0)
    if bad_score.any():
        j = int(np.flatnonzero(bad_score)[0])
        raise FormatError(path, f"{field} joint {j} ({skel.joints[j]}) {score_name}", "a finite number >= 0", score[j])
    bad_xy = (score > 0) & ~np.isfinite(arr[:, :2]).all(axis=1)
    if bad_xy.any():
        j = int(np.flatnonzero(bad_xy)[0])
        xy = [x if math.isfinite(x) else str(x) for x in arr[j, :2].tolist()]
        raise FormatError(path, f"{field} joint {j} ({skel.joints[j]})", "finite x, y pixels", f"{xy}")
    return arr


_NONE = object()
