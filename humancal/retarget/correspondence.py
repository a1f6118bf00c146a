"""Which mocap joint is which body-model point: the stated joint correspondence of the retarget.

Each :class:`JointLink` ties one mocap joint to one *mapped point* of the body model: the head of one of anny's
22 posed bones or one of the 23 canonical keypoints (the *anchor*), plus an optional learned, per-subject
constant offset that rotates with a *carrier* bone::

    p_m = anchor_m + G_carrier(m) @ offset_m

``G_carrier`` is the carrier's world rotation relative to anny's reference pose, so an offset is expressed in
the reference-pose axes (x = the body's left, y = its back, z = up) and stays rigid with the carrier.

Two kinds of offset, because a free offset on a joint *inside* the chain would make its parent bone's rotation
unidentifiable (the offset absorbs any rotation of the parent about the anchor, and the fit then trades bone
rotations for millimetres):

* ``"along"``: one length along the carrier's segment (carrier head -> anchor in the reference pose); it moves
  where the mocap joint sits along the anny bone (e.g. the Daz chest joint lies lower on the spine than anny's
  ``spine01`` head, the Daz shoulder joint medial of anny's gleno-humeral centre) and leaves every rotation
  identifiable. Mirror twins share the length.
* ``"free"``: a 3-D offset, only where the rotation it leaves open is not observed anyway: on the points of a
  chain's end bone (the head's skull base and eyes, the hand's knuckles), where the constant part of that bone's
  orientation is then what the priors decide, and on the pelvis points (the same for the pelvis, whose children
  all have offset-free joints further down). Mirror twins are tied by x -> -x; a midline point's offset has
  x = 0.

The table :data:`DAZ_CMU_LINKS` serves the CMU "Daz-friendly" BVH release (the Aiko3 skeleton, see
``docs/mocap.md`` and ``docs/retarget.md``, which gives the reasons row by row).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from humancal.keypoints import CANONICAL_JOINTS
from humancal.mocap import MocapClip

__all__ = ["JointLink", "DAZ_CMU_LINKS", "ResolvedLinks", "resolve_links", "mocap_targets_m"]

AnchorKind = Literal["bone_head", "keypoint"]
OffsetKind = Literal["none", "along", "free"]


@dataclass(frozen=True)
class JointLink:
    """One row of a joint correspondence table.

    Attributes:
        mocap_joint: joint name in the mocap clip (``MocapClip.joint_names``).
        anchor: a posed bone name (``BodyModel.posed_bones``, for ``kind="bone_head"``) or a canonical keypoint
            name (``humancal.keypoints.CANONICAL_JOINTS``, for ``kind="keypoint"``).
        kind: ``"bone_head"`` (a joint centre of the rig) or ``"keypoint"`` (a skinned surface point).
        carrier: posed bone whose rotation carries the learned offset. For a bone head: the bone or its parent.
        weight: weight of the squared distance of this point in the fit (dimensionless, > 0).
        offset: ``"none"``, ``"along"`` (a learned length along the carrier's segment; the carrier must not be the
            anchor's own bone) or ``"free"`` (a learned 3-D offset; for chain ends only).
        mirror: the ``mocap_joint`` of the left/right twin, or ``None`` for a point on the midline; twins share
            their offset (mirrored).
    """

    mocap_joint: str
    anchor: str
    kind: AnchorKind
    carrier: str
    weight: float = 1.0
    offset: OffsetKind = "none"
    mirror: str | None = None


def _pair(left: str, right: str, anchor_l: str, carrier_l: str, **kwargs) -> tuple[JointLink, JointLink]:
    """A left/right pair of links; the right anchors and carriers are the left ones with ``.L`` -> ``.R``."""

    def right_name(name: str) -> str:
        return name[:-2] + ".R" if name.endswith(".L") else name.replace("left_", "right_")

    return (
        JointLink(left, anchor_l, carrier=carrier_l, mirror=right, **kwargs),
        JointLink(right, right_name(anchor_l), carrier=right_name(carrier_l), mirror=left, **kwargs),
    )


DAZ_CMU_LINKS: tuple[JointLink, ...] = (
    # Pelvis as a rigid body: the Daz hip joint centres (8.8 cm from the midline, anny's about 11 cm; their
    # height and depth in the pelvis differ too), the Daz root ("hip", 2.6 cm below the hip-joint line) and
    # "buttocks" (rig points rigid with the Daz pelvis): free offsets carried by the root. They place the pelvis
    # and turn it frame by frame, its tilt included; the constant part of its rotation is the priors' choice.
    JointLink("hip", "root", "bone_head", carrier="root", weight=0.5, offset="free"),
    *_pair("lButtock", "rButtock", "upperleg01.L", "root", kind="bone_head", weight=0.5, offset="free"),
    *_pair("lThigh", "rThigh", "upperleg01.L", "root", kind="bone_head", offset="free"),
    # Knees and ankles: joint centres in both rigs, no offset: with the elbows and wrists they carry the bone
    # lengths of the shape fit.
    *_pair("lShin", "rShin", "lowerleg01.L", "upperleg01.L", kind="bone_head"),
    *_pair("lFoot", "rFoot", "foot.L", "lowerleg01.L", kind="bone_head"),
    # Daz toe-tip End Site (there is no toe joint) against anny's ball of the foot: a length along the foot, so
    # that the anny foot points where the mocap toes point (a free offset would let the feet turn out or in by
    # whatever the priors like, and the toe and heel keypoints with them).
    *_pair("lFoot_end", "rFoot_end", "toes.L", "foot.L", kind="bone_head", offset="along"),
    # Spine and neck: the vertebra levels of the two rigs differ by a few cm: lengths along the anny segments.
    JointLink("abdomen", "spine03", "bone_head", carrier="spine05", offset="along"),
    JointLink("chest", "spine01", "bone_head", carrier="spine03", offset="along"),
    JointLink("neck", "neck01", "bone_head", carrier="spine01", offset="along"),
    # The head as a rigid body: the Daz skull-base joint (8 cm below the eyes; anny's head joint is 4 cm below
    # them) and eye joints (eyeball centres, ~1.5 cm behind anny's eye keypoints on the surface), all rigid with
    # anny's head bone: a chain end, free offsets. Three points fix the head's pose in every frame, and so where
    # the neck points; the constant part of the head's rotation is the priors' choice. (A length along the neck
    # for the skull base, carried by the neck, let the neck fold down and the head turn back: a 170 deg pair
    # that fits the points as well.)
    JointLink("head", "head", "bone_head", carrier="head", offset="free"),
    *_pair("leftEye", "rightEye", "left_eye", "head", kind="keypoint", weight=0.5, offset="free"),
    # Shoulder joints: the Daz one lies ~7 cm medial of anny's gleno-humeral centre: lengths along the
    # clavicles. (The Daz collar joints, next to the neck, duplicate what the neck and shoulders say; left out.)
    *_pair("lShldr", "rShldr", "upperarm01.L", "clavicle.L", kind="bone_head", offset="along"),
    # Elbows and wrists: joint centres, no offset.
    *_pair("lForeArm", "rForeArm", "lowerarm01.L", "upperarm01.L", kind="bone_head"),
    *_pair("lHand", "rHand", "wrist.L", "lowerarm01.L", kind="bone_head"),
    # Index and little-finger knuckles: anny's fingers are not posed, so these are free offsets from the wrist
    # head carried by the wrist: a chain end; they give the hand's orientation (direction and roll).
    *_pair("lIndex1", "rIndex1", "wrist.L", "wrist.L", kind="bone_head", weight=0.25, offset="free"),
    *_pair("lPinky1", "rPinky1", "wrist.L", "wrist.L", kind="bone_head", weight=0.25, offset="free"),
)
"""The correspondence between the CMU Daz BVH skeleton (read with ``include_end_sites=True``) and anny.

Bone heads (joint centres) are matched wherever the BVH joint is a rotation centre: both are then centres of
rotation, so distances between them are bone lengths in both rigs whatever the pose. Skinned keypoints move on
the surface with the pose, so they are used only where anny has no suitable joint (the eyes). See
``docs/retarget.md`` for the table with reasons."""


@dataclass(frozen=True)
class ResolvedLinks:
    """A correspondence table resolved against a body model's bone and keypoint indices (M mapped points).

    Attributes:
        links: the (M,) links, in table order.
        mocap_joints: (M,) mocap joint names.
        anchor_bone: (M,) posed-bone index of a bone-head anchor, -1 for a keypoint anchor.
        anchor_keypoint: (M,) canonical keypoint index of a keypoint anchor, -1 for a bone-head anchor.
        carrier: (M,) posed-bone index of the carrier.
        weight: (M,) float64 point weights.
        offset_kind: (M,) ``"none"``, ``"along"`` or ``"free"`` per point.
        mirror: (M,) index of each point's mirror twin (itself on the midline).
    """

    links: tuple[JointLink, ...]
    mocap_joints: tuple[str, ...]
    anchor_bone: np.ndarray
    anchor_keypoint: np.ndarray
    carrier: np.ndarray
    weight: np.ndarray
    offset_kind: tuple[str, ...]
    mirror: np.ndarray

    @property
    def num_points(self) -> int:
        """M, the number of mapped points."""
        return len(self.links)

    @property
    def learn_offset(self) -> np.ndarray:
        """(M,) bool: which points have a learned offset."""
        return np.array([kind != "none" for kind in self.offset_kind], dtype=bool)


def _resolve_anchor(
    where: str, link: JointLink, c: int, bone_index: dict[str, int], keypoint_index: dict[str, int],
    posed_bones: Sequence[str], posed_parents: Sequence[int],
) -> tuple[int, int]:
    """``(anchor_bone, anchor_keypoint)`` of one row with carrier index ``c`` (-1 for the kind it is not)."""
    if link.kind == "bone_head":
        if link.anchor not in bone_index:
            raise ValueError(
                f"{where}: anchor {link.anchor!r} is not a posed bone; posed bones: {list(posed_bones)}"
            )
        b = bone_index[link.anchor]
        if c not in (b, posed_parents[b]):
            raise ValueError(
                f"{where}: the carrier of bone head {link.anchor!r} must be the bone itself or its parent "
                f"{posed_bones[posed_parents[b]] if posed_parents[b] >= 0 else '(none)'!r}, got {link.carrier!r}"
            )
        return b, -1
    if link.kind == "keypoint":
        if link.anchor not in keypoint_index:
            raise ValueError(
                f"{where}: anchor {link.anchor!r} is not a canonical keypoint: {list(CANONICAL_JOINTS)}"
            )
        return -1, keypoint_index[link.anchor]
    raise ValueError(f"{where}: kind must be 'bone_head' or 'keypoint', got {link.kind!r}")


def _check_weight_and_offset(where: str, link: JointLink, c: int, bone_index: dict[str, int]) -> None:
    """Raise on a non-positive weight, an unknown offset kind or an ``"along"`` offset carried by its own bone."""
    if not (np.isfinite(link.weight) and link.weight > 0):
        raise ValueError(f"{where}: weight must be positive and finite, got {link.weight!r}")
    if link.offset not in ("none", "along", "free"):
        raise ValueError(f"{where}: offset must be 'none', 'along' or 'free', got {link.offset!r}")
    if link.offset == "along" and link.kind == "bone_head" and c == bone_index[link.anchor]:
        raise ValueError(f"{where}: an 'along' offset needs a carrier other than the anchor's own bone "
                         "(the segment runs from the carrier's head to the anchor)")


def _mirror_row(where: str, i: int, link: JointLink, links: tuple[JointLink, ...], row_of: dict[str, int]) -> int:
    """The row of row ``i``'s mirror twin (``i`` on the midline), checked to point back with the same offset."""
    if link.mirror is None:
        return i
    twin = row_of.get(link.mirror)
    if twin is None or links[twin].mirror != link.mocap_joint or twin == i:
        raise ValueError(
            f"{where}: mirror {link.mirror!r} must be another row whose mirror is {link.mocap_joint!r}"
        )
    if links[twin].offset != link.offset:
        raise ValueError(f"{where}: offset kind differs from its mirror {link.mirror!r}")
    return twin


def resolve_links(
    links: Sequence[JointLink], posed_bones: Sequence[str], posed_parents: Sequence[int]
) -> ResolvedLinks:
    """Check a correspondence table against a body model and turn names into indices.

    Args:
        links: the table (e.g. :data:`DAZ_CMU_LINKS`).
        posed_bones: ``BodyModel.posed_bones``.
        posed_parents: ``BodyModel.posed_parents``.

    Returns:
        The :class:`ResolvedLinks`.

    Raises:
        ValueError: an empty table, a duplicated mocap joint, an unknown anchor or carrier, a bone-head carrier
            that is neither the bone nor its parent, a non-positive weight, or an inconsistent mirror pair.
    """
    links = tuple(links)
    if not links:
        raise ValueError("the joint correspondence table is empty")
    names = tuple(link.mocap_joint for link in links)
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise ValueError(f"joint correspondence: mocap joints listed more than once: {duplicated}")
    bone_index = {name: i for i, name in enumerate(posed_bones)}
    keypoint_index = {name: i for i, name in enumerate(CANONICAL_JOINTS)}
    row_of = {name: i for i, name in enumerate(names)}
    anchor_bone, anchor_keypoint, carrier, mirror = [], [], [], []
    for i, link in enumerate(links):
        where = f"joint correspondence row {i} ({link.mocap_joint!r})"
        if link.carrier not in bone_index:
            raise ValueError(f"{where}: carrier {link.carrier!r} is not a posed bone; posed bones: {list(posed_bones)}")
        c = bone_index[link.carrier]
        b, k = _resolve_anchor(where, link, c, bone_index, keypoint_index, posed_bones, posed_parents)
        anchor_bone.append(b)
        anchor_keypoint.append(k)
        _check_weight_and_offset(where, link, c, bone_index)
        carrier.append(c)
        mirror.append(_mirror_row(where, i, link, links, row_of))
    return ResolvedLinks(
        links=links,
        mocap_joints=names,
        anchor_bone=np.array(anchor_bone, dtype=np.int64),
        anchor_keypoint=np.array(anchor_keypoint, dtype=np.int64),
        carrier=np.array(carrier, dtype=np.int64),
        weight=np.array([link.weight for link in links], dtype=np.float64),
        offset_kind=tuple(link.offset for link in links),
        mirror=np.array(mirror, dtype=np.int64),
    )


def mocap_targets_m(clip: MocapClip, mocap_joints: Sequence[str]) -> np.ndarray:
    """The positions of the mapped mocap joints, in correspondence order.

    Args:
        clip: the mocap clip.
        mocap_joints: (M,) joint names (``ResolvedLinks.mocap_joints``).

    Returns:
        (F, M, 3) float64 world positions, metres.

    Raises:
        ValueError: ``clip`` is not a :class:`MocapClip`, lacks mapped joints (the message lists them), or holds
            non-finite positions.
    """
    if not isinstance(clip, MocapClip):
        raise ValueError(f"expected a humancal.mocap.MocapClip, got {type(clip).__name__}")
    missing = [name for name in mocap_joints if name not in clip.joint_names]
    if missing:
        hint = " (read BVH files with include_end_sites=True for the *_end joints)" if any(
            n.endswith("_end") for n in missing
        ) else ""
        raise ValueError(
            f"clip {clip.name!r} lacks the mapped mocap joint(s) {missing}{hint}; it has {list(clip.joint_names)}"
        )
    targets = np.asarray(clip.positions_world_m)[:, [clip.joint_index(n) for n in mocap_joints]]
    bad = ~np.isfinite(targets).all(axis=-1)
    if bad.any():
        frame, point = np.argwhere(bad)[0]
        raise ValueError(
            f"clip {clip.name!r}: {int(bad.sum())} mapped joint position(s) are non-finite, first at frame {frame}, "
            f"joint {mocap_joints[point]!r}"
        )
    return targets
