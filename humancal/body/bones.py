"""The compact set of bones that humancal poses, and how each one maps onto anny's 104-bone rig.

The set mirrors the 22 body joints of SMPL (same order: pelvis, hips, spine, knees, ..., wrists), expressed
with anny's bone names. Every posed bone drives one anny bone, except the toes: anny has one bone per toe,
and the big-toe and small-toe keypoints hang on different toes (``toe1-2`` and ``toe5-3``), so posing only
``toe1-1`` would bend the big toe while leaving the small toe rigid with the foot. ``toes.L``/``toes.R``
therefore apply one rotation to the five proximal toe bones at once (each about its own head, in the same
world-aligned axes), which is what a mocap "toes" joint means. Every other anny bone (twist bones
``*02``, ``pelvis.*``, ``shoulder01.*``, ``spine04``, ``spine02``, ``neck02/03``, fingers, distal toes, eyes)
stays at the identity delta and follows its nearest posed ancestor rigidly.
"""

from __future__ import annotations

__all__ = ["POSED_BONE_SPEC", "POSED_BONE_NAMES", "ANNY_BONES_OF"]

_TOES_L = ("toe1-1.L", "toe2-1.L", "toe3-1.L", "toe4-1.L", "toe5-1.L")
_TOES_R = ("toe1-1.R", "toe2-1.R", "toe3-1.R", "toe4-1.R", "toe5-1.R")

POSED_BONE_SPEC: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("root", ("root",)),
    ("upperleg01.L", ("upperleg01.L",)),
    ("upperleg01.R", ("upperleg01.R",)),
    ("spine05", ("spine05",)),
    ("lowerleg01.L", ("lowerleg01.L",)),
    ("lowerleg01.R", ("lowerleg01.R",)),
    ("spine03", ("spine03",)),
    ("foot.L", ("foot.L",)),
    ("foot.R", ("foot.R",)),
    ("spine01", ("spine01",)),
    ("toes.L", _TOES_L),
    ("toes.R", _TOES_R),
    ("neck01", ("neck01",)),
    ("clavicle.L", ("clavicle.L",)),
    ("clavicle.R", ("clavicle.R",)),
    ("head", ("head",)),
    ("upperarm01.L", ("upperarm01.L",)),
    ("upperarm01.R", ("upperarm01.R",)),
    ("lowerarm01.L", ("lowerarm01.L",)),
    ("lowerarm01.R", ("lowerarm01.R",)),
    ("wrist.L", ("wrist.L",)),
    ("wrist.R", ("wrist.R",)),
)
"""(posed bone name, anny bones it drives), root first, parents before children. The first anny bone of a
group is the one whose head the posed bone's joint position reports (``toes.*``: the big toe's root)."""

POSED_BONE_NAMES: tuple[str, ...] = tuple(name for name, _ in POSED_BONE_SPEC)

ANNY_BONES_OF: dict[str, tuple[str, ...]] = dict(POSED_BONE_SPEC)
