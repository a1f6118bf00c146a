"""Procedural multi-person motion: activity schedules -> ground paths -> joint angles -> body-model poses,
with the feet put on the floor.

Feet on the floor is done the simple, honest way: after forward kinematics each frame's root is raised or
lowered so that the lowest foot keypoint (ankles, toes, heels) touches z = 0, which also yields the vertical
bob of walking (and the seat height of a seated person: feet flat, so the pelvis sits at knee height).
While crouching, sitting or bending over, the root is additionally moved so that the ankles stay where the
person stood (the hips go back when the knees go forward). Walking feet may slide a little: steps are sized
from speed and leg length, not planted by inverse kinematics.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import torch

from humancal.body import BodyModel, RestSkeleton
from humancal.keypoints import joint_indices
from humancal.synthetic.activities import ACTIVITIES, ActivityTrack, activity_track, plan_activities
from humancal.synthetic.gait import draw_style, gait_channels
from humancal.synthetic.paths import Paths, seated_paths, simulate_paths
from humancal.synthetic.poses import arm_geometry, channels_to_rotmats

__all__ = ["Motions", "generate_motions", "FOOT_JOINTS"]

logger = logging.getLogger(__name__)

FOOT_JOINTS: tuple[str, ...] = (
    "left_ankle",
    "right_ankle",
    "left_big_toe",
    "right_big_toe",
    "left_small_toe",
    "right_small_toe",
    "left_heel",
    "right_heel",
)
"""Keypoints that may touch the floor."""
_FOOT_INDEX = joint_indices(FOOT_JOINTS)
_ANKLE_INDEX = joint_indices(["left_ankle", "right_ankle"])


@dataclass(frozen=True)
class Motions:
    """Ground-truth motion of P people over F frames.

    Attributes:
        bone_rotmats_local: (P, F, B, 3, 3) "local-ref" bone rotations (``BodyModel.posed_bones`` order;
            bone 0 is the global orientation), exactly as fed to the body model.
        root_translation_m: (P, F, 3) world position of the root (pelvis) bone head, metres.
        keypoints_world_m: (P, F, 23, 3) canonical keypoints, world metres, Z up.
        activity: (P, F) index into ``humancal.synthetic.activities.ACTIVITIES`` of each frame's activity.
        heading_rad: (P, F) facing direction in the ground plane, radians from +x towards +y.
    """

    bone_rotmats_local: np.ndarray
    root_translation_m: np.ndarray
    keypoints_world_m: np.ndarray
    activity: np.ndarray
    heading_rad: np.ndarray

    @property
    def activity_names(self) -> tuple[str, ...]:
        """Names of the activity codes."""
        return ACTIVITIES


def _leg_length_m(bone_heads_m: np.ndarray, posed_bones: tuple[str, ...]) -> float:
    index = {name: i for i, name in enumerate(posed_bones)}
    hip, knee, ankle = (bone_heads_m[index[b]] for b in ("upperleg01.L", "lowerleg01.L", "foot.L"))
    return float(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee))


def person_pose(body: BodyModel, bone_heads_m: np.ndarray, track: ActivityTrack, paths: Paths, person: int,
                fps: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One person's pose along their path: a gait style drawn from ``rng``, the gait channels of their activity
    ``track``, turned into body-model rotations facing the path's heading.

    Args:
        bone_heads_m: (B, 3) the person's rest bone heads (``RestSkeleton.bone_heads_m``), metres.
        paths: every person's ground paths; ``person`` picks theirs.

    Returns:
        rotmats: (F, B, 3, 3) local bone rotations; root_xy_m: (F, 2) root ground position (path plus sway), metres.
    """
    style = draw_style(rng)
    channels, sway = gait_channels(track, paths, person, _leg_length_m(bone_heads_m, body.posed_bones), style, fps,
                                   rng)
    heading = paths.heading_rad[person]
    # The reference body faces -y: yaw psi + pi/2 makes it face heading psi.
    geometry = arm_geometry(bone_heads_m, body.posed_bones)
    rotmats = channels_to_rotmats(channels, heading + 0.5 * np.pi, geometry, body.posed_bones)
    forward = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    left = np.stack([-np.sin(heading), np.cos(heading)], axis=1)
    return rotmats, paths.position_m[person] + sway[:, :1] * left + sway[:, 1:] * forward


def _keypoints(body: BodyModel, rest: RestSkeleton, rotmats: torch.Tensor, translation_m: np.ndarray) -> np.ndarray:
    translation = torch.as_tensor(translation_m, dtype=body.dtype, device=body.device)
    with torch.no_grad():
        return body.keypoints(rest, rotmats, translation).double().cpu().numpy()


def generate_motions(
    body: BodyModel,
    rest: RestSkeleton,
    num_frames: int,
    fps: float,
    area_size_m: tuple[float, float],
    rng: np.random.Generator,
    behaviour: str = "mixed",
) -> Motions:
    """Random activities for every person of ``rest``, simulated together in one capture area.

    Args:
        body: the body model.
        rest: :meth:`BodyModel.rest_skeleton` of the P people.
        num_frames: F >= 1.
        fps: frames per second.
        area_size_m: (x, y) size of the capture area centred on the origin, metres.
        rng: source of randomness.
        behaviour: ``"mixed"``, ``"seated"`` (everyone seated at a fixed spot all the time) or ``"low"``
            (mostly sitting, crouching and bending over); see ``SceneConfig.behaviour``.

    Returns:
        The :class:`Motions`.

    Raises:
        ValueError: unknown behaviour.
    """
    num_people = rest.num_people
    tracks = [
        activity_track(plan_activities(num_frames, fps, rng, behaviour), num_frames, fps, rng)
        for _ in range(num_people)
    ]
    if behaviour == "seated":
        paths = seated_paths(num_people, num_frames, area_size_m, fps, rng)
    else:
        paths = simulate_paths(tracks, area_size_m, fps, rng)
    heads = rest.bone_heads_m.detach().double().cpu().numpy()

    rotmats = np.empty((num_people, num_frames, body.num_posed_bones, 3, 3))
    root_xy = np.empty((num_people, num_frames, 2))
    for p in range(num_people):
        rotmats[p], root_xy[p] = person_pose(body, heads[p], tracks[p], paths, p, fps, rng)

    rotmats_t = torch.as_tensor(rotmats, dtype=body.dtype, device=body.device)
    rotmats = rotmats_t.double().cpu().numpy()  # exactly what the body model sees
    translation = np.concatenate([root_xy, np.zeros((num_people, num_frames, 1))], axis=-1)
    keypoints = _keypoints(body, rest, rotmats_t, translation)

    # Lowest foot point on the floor; while crouching, sitting or bending, keep the ankles above the spot the
    # person stands on.
    translation[..., 2] = -keypoints[..., _FOOT_INDEX, 2].min(axis=-1)
    crouch = np.stack([t.crouch for t in tracks])
    if behaviour != "mixed":
        crouch = crouch + np.stack([t.sit + t.bend for t in tracks])
    ankle_xy = keypoints[..., _ANKLE_INDEX, :2].mean(axis=-2)
    # Full anchoring from a quarter of the crouch depth on (the offset is still small there).
    anchor = np.clip(4.0 * crouch, 0.0, 1.0)
    translation[..., :2] -= anchor[..., None] * (ankle_xy - root_xy)
    translation = torch.as_tensor(translation, dtype=body.dtype).double().numpy()
    keypoints = _keypoints(body, rest, rotmats_t, translation)
    logger.debug("motions: %d people x %d frames", num_people, num_frames)
    return Motions(
        bone_rotmats_local=rotmats,
        root_translation_m=translation,
        keypoints_world_m=keypoints,
        activity=np.stack([t.label for t in tracks]),
        heading_rad=paths.heading_rad.copy(),
    )
