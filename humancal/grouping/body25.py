"""OpenPose BODY_25: joint order and the limbs its part-affinity fields connect.

The joint names and order are those of the skeleton registry (``humancal.formats.skeletons``, OpenPose's
``Nose, Neck, RShoulder, ..., RHeel`` in snake_case). The limb order is the order in which OpenPose (and the
4D Association files, ``docs/shelf.md``) list the 26 part-affinity fields; 24 of them form a spanning tree of the
25 joints rooted at the neck, the two shoulder-to-ear limbs are redundant links.
"""

from __future__ import annotations

from humancal.formats.skeletons import get_skeleton

__all__ = ["BODY25_INDEX", "BODY25_JOINTS", "BODY25_LIMBS", "BODY25_ROOT", "BODY25_TREE_LIMBS"]

BODY25_JOINTS: tuple[str, ...] = get_skeleton("body25").joints
"""BODY_25 joint names in OpenPose's array order (nose, neck, right_shoulder, ..., right_heel)."""

BODY25_INDEX: dict[str, int] = {name: i for i, name in enumerate(BODY25_JOINTS)}

BODY25_LIMBS: tuple[tuple[int, int], ...] = (
    (1, 8),
    (9, 10),
    (10, 11),
    (8, 9),
    (8, 12),
    (12, 13),
    (13, 14),
    (1, 2),
    (2, 3),
    (3, 4),
    (2, 17),
    (1, 5),
    (5, 6),
    (6, 7),
    (5, 18),
    (1, 0),
    (0, 15),
    (0, 16),
    (15, 17),
    (16, 18),
    (14, 19),
    (19, 20),
    (14, 21),
    (11, 22),
    (22, 23),
    (11, 24),
)
"""The 26 BODY_25 part-affinity limbs as (joint a, joint b) index pairs, in OpenPose's PAF order."""

BODY25_ROOT = 1
"""The neck: root of the BODY_25 limb tree."""

BODY25_TREE_LIMBS: tuple[tuple[int, int], ...] = tuple(limb for limb in BODY25_LIMBS if limb not in ((2, 17), (5, 18)))
"""The 24 limbs forming a spanning tree of the 25 joints (the two shoulder-to-ear limbs left out)."""
