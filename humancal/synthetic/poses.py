"""From a few anatomical joint angles ("channels") to the body model's bone rotations.

The body model (``docs/body_model.md``) poses bones with "local-ref" rotations: each bone's rotation is
expressed in world-aligned axes of the reference pose (upright, facing -y, left side at +x, Z up), composed
child after parent. In those axes the anatomical motions are simple:

* flexion of hips, knees, ankles, toes, spine and shoulders is a rotation about +x (the body's left-right
  axis); a positive angle about +x swings a downward segment backwards and leans an upward one forwards;
* abduction of a limb is a rotation about +y, with opposite signs left and right;
* twists (yaw) are rotations about +z.

The elbow is the exception: anny's reference arms hang in an "A" (about 40 degrees from vertical) with the
elbows already bent, so the elbow hinge axis and the rest bend are measured per person from the rest skeleton
(:class:`ArmGeometry`). Right-side rotations are the mirror images (x -> -x) of the left-side ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.geometry.rotations import angle_between_deg, axis_angle_to_rotmat

__all__ = [
    "CHANNELS",
    "CHANNEL_INDEX",
    "ArmGeometry",
    "arm_geometry",
    "axis_angle_to_rotmat",
    "channels_to_rotmats",
    "REQUIRED_BONES",
]

CHANNELS: tuple[str, ...] = (
    "hip_flex_l",
    "hip_flex_r",
    "hip_abd_l",
    "hip_abd_r",
    "knee_flex_l",
    "knee_flex_r",
    "foot_pitch_l",
    "foot_pitch_r",
    "toe_ext_l",
    "toe_ext_r",
    "spine_lean",
    "spine_side",
    "spine_twist",
    "neck_pitch",
    "neck_yaw",
    "shoulder_flex_l",
    "shoulder_flex_r",
    "arm_elev_l",
    "arm_elev_r",
    "arm_twist_l",
    "arm_twist_r",
    "elbow_flex_l",
    "elbow_flex_r",
    "pelvis_yaw",
    "pelvis_roll",
    "pelvis_pitch",
)
"""Joint-angle channels, degrees. Meanings (positive direction):

* ``hip_flex_*``: thigh forward; ``hip_abd_*``: thigh outward; ``knee_flex_*``: shank backward relative to
  the thigh; ``foot_pitch_*``: toes up relative to the floor plane (the ankle angle that keeps it is derived);
  ``toe_ext_*``: toes up relative to the foot.
* ``spine_lean``: trunk forward; ``spine_side``: trunk to the left; ``spine_twist``: shoulders turn left;
  ``neck_pitch``: head down; ``neck_yaw``: head turns left.
* ``shoulder_flex_*``: arm forward; ``arm_elev_*``: angle of the upper arm from vertical in the body's
  frontal plane (0 = hanging); ``arm_twist_*``: external rotation of the upper arm about its own axis;
  ``elbow_flex_*``: forearm bend (0 = straight arm).
* ``pelvis_yaw``: pelvis turns left (relative to the heading); ``pelvis_roll``: pelvis tilts left side down;
  ``pelvis_pitch``: pelvis (and with it the trunk) tilts forward; the thighs turn with it, so a hip flexion
  of the same angle keeps them where they were (bending over with straight legs, leaning while seated).
"""

CHANNEL_INDEX: dict[str, int] = {name: i for i, name in enumerate(CHANNELS)}

REQUIRED_BONES: tuple[str, ...] = (
    "root",
    "upperleg01.L",
    "upperleg01.R",
    "spine05",
    "lowerleg01.L",
    "lowerleg01.R",
    "spine03",
    "foot.L",
    "foot.R",
    "spine01",
    "toes.L",
    "toes.R",
    "neck01",
    "head",
    "upperarm01.L",
    "upperarm01.R",
    "lowerarm01.L",
    "lowerarm01.R",
    "wrist.L",
)
"""Posed bones (``BodyModel.posed_bones``) that the channels drive or that define the arm geometry."""

_FORWARD = np.array([0.0, -1.0, 0.0])
"""The reference pose faces -y."""
_MIRROR = np.array([-1.0, 1.0, 1.0])


def _rot(axis: str, angle_deg: np.ndarray) -> np.ndarray:
    unit = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}[axis]
    return axis_angle_to_rotmat(np.array(unit), np.deg2rad(angle_deg))


@dataclass(frozen=True)
class ArmGeometry:
    """Per-person arm geometry of the reference pose (left arm; the right arm is its mirror image).

    Attributes:
        upper_arm_dir: (3,) unit vector shoulder -> elbow in the reference pose.
        rest_elev_deg: angle of the upper arm from vertical in the frontal plane, degrees.
        elbow_axis: (3,) unit hinge axis of the elbow (positive rotation bends the forearm forwards),
            reference axes.
        rest_elbow_deg: elbow bend of the reference pose, degrees.
    """

    upper_arm_dir: np.ndarray
    rest_elev_deg: float
    elbow_axis: np.ndarray
    rest_elbow_deg: float


def arm_geometry(bone_heads_m: np.ndarray, posed_bones: tuple[str, ...]) -> ArmGeometry:
    """Measure the left arm of one person's reference pose.

    Args:
        bone_heads_m: (B, 3) posed-bone heads of the reference pose (``RestSkeleton.bone_heads_m[p]``), metres.
        posed_bones: ``BodyModel.posed_bones``.

    Returns:
        The :class:`ArmGeometry`.
    """
    index = {name: i for i, name in enumerate(posed_bones)}
    shoulder = bone_heads_m[index["upperarm01.L"]]
    elbow = bone_heads_m[index["lowerarm01.L"]]
    wrist = bone_heads_m[index["wrist.L"]]
    upper = (elbow - shoulder) / np.linalg.norm(elbow - shoulder)
    fore = (wrist - elbow) / np.linalg.norm(wrist - elbow)
    rest_elev = np.degrees(np.arctan2(upper[0], -upper[2]))
    hinge = np.cross(upper, _FORWARD)
    hinge /= np.linalg.norm(hinge)
    rest_bend = angle_between_deg(upper, fore)
    return ArmGeometry(upper, float(rest_elev), hinge, float(rest_bend))


def _arm_rotations(channels: np.ndarray, geometry: ArmGeometry, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Upper-arm and forearm local rotations of one side (the right side mirrored), each (F, 3, 3)."""
    names = ("shoulder_flex", "arm_elev", "arm_twist", "elbow_flex")
    c = {name: channels[:, CHANNEL_INDEX[f"{name}_{side}"]] for name in names}
    sign = 1.0 if side == "l" else -1.0
    mirror = np.ones(3) if side == "l" else _MIRROR
    upper_dir = geometry.upper_arm_dir * mirror
    # A rotation about an axis a mirrors to a rotation about -M a by the same angle (M: x -> -x).
    twist = axis_angle_to_rotmat(sign * upper_dir, np.deg2rad(-c["arm_twist"]))
    elevate = _rot("y", sign * (geometry.rest_elev_deg - c["arm_elev"]))
    flex = _rot("x", -c["shoulder_flex"])
    upper = flex @ elevate @ twist
    hinge = np.cross(upper_dir, _FORWARD)
    hinge /= np.linalg.norm(hinge)
    fore = axis_angle_to_rotmat(hinge, np.deg2rad(c["elbow_flex"] - geometry.rest_elbow_deg))
    return upper, fore


def channels_to_rotmats(
    channels_deg: np.ndarray,
    body_yaw_rad: np.ndarray,
    geometry: ArmGeometry,
    posed_bones: tuple[str, ...],
) -> np.ndarray:
    """Bone rotations of one person over time.

    Args:
        channels_deg: (F, C) joint angles, degrees, columns :data:`CHANNELS`.
        body_yaw_rad: (F,) rotation of the whole body about +z from the reference pose, radians (the reference
            faces -y, so a body walking towards heading ``psi`` has yaw ``psi + pi/2``).
        geometry: the person's :class:`ArmGeometry`.
        posed_bones: ``BodyModel.posed_bones``; bones without a channel stay identity.

    Returns:
        (F, B, 3, 3) "local-ref" rotations (bone 0: global orientation).

    Raises:
        ValueError: wrong channel count, or a bone of :data:`REQUIRED_BONES` missing from ``posed_bones``.
    """
    channels = np.asarray(channels_deg, dtype=np.float64)
    if channels.ndim != 2 or channels.shape[1] != len(CHANNELS):
        raise ValueError(f"channels_deg must be (F, {len(CHANNELS)}), got {channels.shape}")
    missing = [b for b in REQUIRED_BONES if b not in posed_bones]
    if missing:
        raise ValueError(f"posed_bones lacks {missing}; the synthetic poses need {list(REQUIRED_BONES)}")
    num_frames = channels.shape[0]
    index = {name: i for i, name in enumerate(posed_bones)}
    out = np.broadcast_to(np.eye(3), (num_frames, len(posed_bones), 3, 3)).copy()

    def ch(name: str) -> np.ndarray:
        return channels[:, CHANNEL_INDEX[name]]

    yaw_deg = np.degrees(np.asarray(body_yaw_rad, dtype=np.float64)) + ch("pelvis_yaw")
    out[:, index["root"]] = _rot("z", yaw_deg) @ _rot("y", ch("pelvis_roll"))
    pitch = ch("pelvis_pitch")
    tilted = bool(np.any(pitch))
    if tilted:
        out[:, index["root"]] = out[:, index["root"]] @ _rot("x", pitch)
    for side, bone in (("l", "L"), ("r", "R")):
        sign = 1.0 if side == "l" else -1.0
        hip, knee = ch(f"hip_flex_{side}"), ch(f"knee_flex_{side}")
        out[:, index[f"upperleg01.{bone}"]] = _rot("x", -hip) @ _rot("y", -sign * ch(f"hip_abd_{side}"))
        out[:, index[f"lowerleg01.{bone}"]] = _rot("x", knee)
        # The foot's pitch in the world is pelvis pitch - hip + knee - dorsiflexion (about +x); solve for the ankle.
        dorsiflexion = knee - hip + ch(f"foot_pitch_{side}")
        if tilted:
            dorsiflexion = dorsiflexion + pitch
        out[:, index[f"foot.{bone}"]] = _rot("x", -dorsiflexion)
        out[:, index[f"toes.{bone}"]] = _rot("x", -ch(f"toe_ext_{side}"))
        upper, fore = _arm_rotations(channels, geometry, side)
        out[:, index[f"upperarm01.{bone}"]] = upper
        out[:, index[f"lowerarm01.{bone}"]] = fore
    # The trunk bends over three spine bones, the head over neck and head.
    spine = _rot("z", ch("spine_twist") / 3.0) @ _rot("x", ch("spine_lean") / 3.0) @ _rot("y", ch("spine_side") / 3.0)
    for bone in ("spine05", "spine03", "spine01"):
        out[:, index[bone]] = spine
    neck = _rot("z", ch("neck_yaw") / 2.0) @ _rot("x", ch("neck_pitch") / 2.0)
    out[:, index["neck01"]] = neck
    out[:, index["head"]] = neck
    return out
