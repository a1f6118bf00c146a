"""Keypoints of any registered skeleton to and from the canonical 23 joints.

A joint is *present* when its score is positive and its coordinates are finite; an absent joint has score 0 and
NaN coordinates, in the inputs' interpretation and in every output of this module.

``to_canonical`` picks each canonical joint from the source skeleton by name; canonical joints the skeleton lacks
(feet of COCO-17, face of SHELF15, ...) come out absent. No canonical joint is guessed from others.

``from_canonical`` picks each target joint from the canonical set by name; a target joint the canonical set lacks
is computed by one of the rules of :data:`DERIVED_JOINTS` (all of them here, in one place), or comes out absent
when no rule exists (e.g. the face points of COCO-WholeBody) or the rule does not apply to the coordinates' dimension.
A derived joint is present only where all its source joints are; its score is the minimum of theirs.

The rules:

* ``neck``: midpoint of the shoulders (any dimension).
* ``mid_hip`` and ``pelvis``: midpoint of the hips (any dimension).
* ``bottom_head``: the neck (midpoint of the shoulders) moved halfway toward the nose,
  ``neck + 0.5 (nose - neck)`` (any dimension).
* ``top_head``: ``neck + s * (nose - neck)`` with per-axis scale ``s = (0.75, 0.75, 1.5)``: the nose offset is
  shortened horizontally and lengthened vertically. **3D only, world Z up** (the scale singles out the world's
  vertical axis, which has no counterpart in an image); with 2D keypoints ``top_head`` is absent.

The two head rules are those published with mvpose (Dong et al., CVPR 2019) for evaluating COCO-style
predictions against the Shelf and Campus ground truth, which have no nose but a bottom-head and a top-head joint.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from humancal.formats.skeletons import Skeleton, get_skeleton
from humancal.keypoints import CANONICAL_JOINTS, JOINT_INDEX, NUM_JOINTS

__all__ = ["DerivedJoint", "DERIVED_JOINTS", "to_canonical", "from_canonical"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class DerivedJoint:
    """A joint computed from canonical joints.

    Attributes:
        name: the joint's name.
        sources: canonical joints it is computed from (all must be present).
        rule: the rule in words.
        dims: coordinate dimensions (2 = image, 3 = world) the rule applies to.
        compute: ``compute(points)`` where ``points[name]`` is the (..., D) array of source joint ``name``;
            returns the (..., D) derived joint.
    """

    name: str
    sources: tuple[str, ...]
    rule: str
    dims: tuple[int, ...]
    compute: Callable[[dict[str, np.ndarray]], np.ndarray]


def _midpoint(a: str, b: str) -> Callable[[dict[str, np.ndarray]], np.ndarray]:
    return lambda p: 0.5 * (p[a] + p[b])


def _neck(p: dict[str, np.ndarray]) -> np.ndarray:
    return 0.5 * (p["left_shoulder"] + p["right_shoulder"])


def _bottom_head(p: dict[str, np.ndarray]) -> np.ndarray:
    neck = _neck(p)
    return neck + 0.5 * (p["nose"] - neck)


_TOP_HEAD_SCALE = np.array([0.75, 0.75, 1.5])
"""Per-axis scale of the neck-to-nose offset giving the top of the head (x, y horizontal, z up)."""


def _top_head(p: dict[str, np.ndarray]) -> np.ndarray:
    neck = _neck(p)
    return neck + _TOP_HEAD_SCALE * (p["nose"] - neck)


_SHOULDERS = ("left_shoulder", "right_shoulder")
_HIPS = ("left_hip", "right_hip")

DERIVED_JOINTS: dict[str, DerivedJoint] = {
    d.name: d
    for d in (
        DerivedJoint("neck", _SHOULDERS, "midpoint of the shoulders", (2, 3), _neck),
        DerivedJoint("mid_hip", _HIPS, "midpoint of the hips", (2, 3), _midpoint(*_HIPS)),
        DerivedJoint("pelvis", _HIPS, "midpoint of the hips", (2, 3), _midpoint(*_HIPS)),
        DerivedJoint(
            "bottom_head",
            ("nose", *_SHOULDERS),
            "neck (midpoint of the shoulders) moved halfway toward the nose (mvpose)",
            (2, 3),
            _bottom_head,
        ),
        DerivedJoint(
            "top_head",
            ("nose", *_SHOULDERS),
            "neck + (nose - neck) scaled by 0.75 in x and y and 1.5 in z, world Z up (mvpose); 3D only",
            (3,),
            _top_head,
        ),
    )
}
"""Every rule that computes a non-canonical joint from canonical ones, by joint name."""


def to_canonical(
    keypoints: np.ndarray, scores: np.ndarray, skeleton: str | Skeleton
) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints of ``skeleton`` to the canonical 23 joints.

    Args:
        keypoints: (..., J, D) coordinates in the skeleton's joint order (pixels for D = 2, metres for D = 3).
        scores: (..., J) confidences; a joint with score <= 0 or non-finite coordinates is absent.
        skeleton: the source skeleton or its name (:data:`humancal.formats.skeletons.SKELETONS`).

    Returns:
        keypoints: (..., 23, D) in canonical order, NaN where absent.
        scores: (..., 23), 0 where absent (canonical joints the skeleton lacks are always absent).

    Raises:
        ValueError: shapes do not match the skeleton (the message gives expected and received shapes).
    """
    skel = get_skeleton(skeleton)
    kp, sc, present = _checked(keypoints, scores, skel.num_joints, f"skeleton '{skel.name}'")
    source = [skel.joints.index(name) if name in skel.joints else -1 for name in CANONICAL_JOINTS]
    out_kp = np.full(kp.shape[:-2] + (NUM_JOINTS, kp.shape[-1]), np.nan)
    out_sc = np.zeros(kp.shape[:-2] + (NUM_JOINTS,))
    for c, j in enumerate(source):
        if j < 0:
            continue
        ok = present[..., j]
        out_kp[..., c, :] = np.where(ok[..., None], kp[..., j, :], np.nan)
        out_sc[..., c] = np.where(ok, sc[..., j], 0.0)
    return out_kp, out_sc


def from_canonical(
    keypoints: np.ndarray, scores: np.ndarray, skeleton: str | Skeleton
) -> tuple[np.ndarray, np.ndarray]:
    """Canonical keypoints to the joints of ``skeleton``, deriving joints the canonical set lacks.

    Args:
        keypoints: (..., 23, D) canonical keypoints (pixels for D = 2; metres, world Z up for D = 3).
        scores: (..., 23) confidences; a joint with score <= 0 or non-finite coordinates is absent.
        skeleton: the target skeleton or its name.

    Returns:
        keypoints: (..., J, D) in the skeleton's order, NaN where absent.
        scores: (..., J), 0 where absent. Derived joints (:data:`DERIVED_JOINTS`) get the minimum score of their
        sources; joints with no source and no applicable rule are absent.

    Raises:
        ValueError: shapes are not (..., 23, D) and (..., 23).
    """
    skel = get_skeleton(skeleton)
    kp, sc, present = _checked(keypoints, scores, NUM_JOINTS, "the canonical set")
    dim = kp.shape[-1]
    out_kp = np.full(kp.shape[:-2] + (skel.num_joints, dim), np.nan)
    out_sc = np.zeros(kp.shape[:-2] + (skel.num_joints,))
    unfilled = []
    for j, name in enumerate(skel.joints):
        if name in JOINT_INDEX:
            c = JOINT_INDEX[name]
            ok = present[..., c]
            out_kp[..., j, :] = np.where(ok[..., None], kp[..., c, :], np.nan)
            out_sc[..., j] = np.where(ok, sc[..., c], 0.0)
        elif name in DERIVED_JOINTS and dim in DERIVED_JOINTS[name].dims:
            rule = DERIVED_JOINTS[name]
            idx = [JOINT_INDEX[s] for s in rule.sources]
            ok = present[..., idx].all(axis=-1)
            with np.errstate(invalid="ignore"):
                value = rule.compute({s: kp[..., JOINT_INDEX[s], :] for s in rule.sources})
            out_kp[..., j, :] = np.where(ok[..., None], value, np.nan)
            out_sc[..., j] = np.where(ok, sc[..., idx].min(axis=-1), 0.0)
        else:
            unfilled.append(name)
    if unfilled:
        logger.debug("from_canonical to '%s' (D=%d): no source for %s; left absent", skel.name, dim, unfilled)
    return out_kp, out_sc


def _checked(
    keypoints: np.ndarray, scores: np.ndarray, num_joints: int, what: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    kp = np.asarray(keypoints, dtype=np.float64)
    sc = np.asarray(scores, dtype=np.float64)
    if kp.ndim < 2 or kp.shape[-2] != num_joints or kp.shape[-1] not in (2, 3):
        raise ValueError(f"keypoints of {what}: expected shape (..., {num_joints}, 2 or 3), got {kp.shape}")
    if sc.shape != kp.shape[:-1]:
        raise ValueError(
            f"scores of {what}: expected shape {kp.shape[:-1]} (keypoints without the last axis), got {sc.shape}"
        )
    with np.errstate(invalid="ignore"):
        present = (sc > 0) & np.isfinite(kp).all(axis=-1) & np.isfinite(sc)
    return kp, sc, present
