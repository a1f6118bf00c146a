"""People, joint-angle channels and procedural motions on the real body model."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from humancal.keypoints import JOINT_INDEX
from humancal.synthetic import ACTIVITIES, generate_motions, sample_people
from humancal.synthetic.activities import plan_activities, smooth
from humancal.synthetic.motions import FOOT_JOINTS
from humancal.synthetic.people import phenotypes_for_heights
from humancal.synthetic.poses import CHANNEL_INDEX, CHANNELS, arm_geometry, axis_angle_to_rotmat, channels_to_rotmats

AREA_M = (5.0, 4.0)


@pytest.fixture(scope="module")
def people(body_model):
    return sample_people(body_model, 4, np.random.default_rng(1), height_range_m=(1.5, 1.95))


@pytest.fixture(scope="module")
def rest(body_model, people):
    return body_model.rest_skeleton(torch.as_tensor(people.phenotypes, dtype=body_model.dtype))


@pytest.fixture(scope="module")
def motions(body_model, rest):
    return generate_motions(body_model, rest, 240, 30.0, AREA_M, np.random.default_rng(2))


def _pose(body_model, rest, channels: dict[str, float], yaw_rad: float = 0.0) -> np.ndarray:
    values = np.zeros((1, len(CHANNELS)))
    for name, value in channels.items():
        values[0, CHANNEL_INDEX[name]] = value
    geometry = arm_geometry(rest.bone_heads_m[0].double().numpy(), body_model.posed_bones)
    rotmats = channels_to_rotmats(values, np.array([yaw_rad]), geometry, body_model.posed_bones)
    rotmats = torch.as_tensor(rotmats, dtype=body_model.dtype)[None].expand(rest.num_people, -1, -1, -1, -1)
    with torch.no_grad():
        kp = body_model.keypoints(rest, rotmats.contiguous(), torch.zeros(rest.num_people, 1, 3))
    return kp[0, 0].double().numpy()


def test_people_heights_and_ids(body_model, people):
    assert people.person_ids.tolist() == [0, 1, 2, 3]
    assert np.all((people.height_m >= 1.5) & (people.height_m <= 1.95))
    assert np.all((people.phenotypes >= 0.0) & (people.phenotypes <= 1.0))
    assert len(np.unique(people.phenotypes[:, 0].round(3))) == 4  # varied bodies
    measured = body_model.height_m(torch.as_tensor(people.phenotypes, dtype=body_model.dtype)).double().numpy()
    np.testing.assert_allclose(measured, people.height_m, atol=1e-6)


def test_phenotypes_for_heights_hits_targets_and_rejects_unreachable(body_model):
    base = np.full((3, 6), 0.5)
    solved = phenotypes_for_heights(body_model, base, np.array([1.55, 1.7, 1.9]))
    heights = body_model.height_m(torch.as_tensor(solved, dtype=body_model.dtype)).double().numpy()
    np.testing.assert_allclose(heights, [1.55, 1.7, 1.9], atol=2e-4)
    with pytest.raises(ValueError, match=r"target_height_m\[0\]=3.000 m is unreachable"):
        phenotypes_for_heights(body_model, base[:1], np.array([3.0]))


def test_channels_move_the_body_the_documented_way(body_model, rest):
    j = JOINT_INDEX
    still = _pose(body_model, rest, {})
    # Reference: upright, facing -y, left side at +x.
    assert still[j["nose"], 1] < still[j["left_ear"], 1]
    assert still[j["left_shoulder"], 0] > 0 > still[j["right_shoulder"], 0]
    hip = _pose(body_model, rest, {"hip_flex_l": 40.0})
    assert hip[j["left_knee"], 1] < still[j["left_knee"], 1] - 0.1  # knee forward (-y)
    knee = _pose(body_model, rest, {"knee_flex_r": 60.0})
    assert knee[j["right_ankle"], 1] > still[j["right_ankle"], 1] + 0.2  # shank backward
    lean = _pose(body_model, rest, {"spine_lean": 30.0})
    assert lean[j["nose"], 1] < still[j["nose"], 1] - 0.1
    # Arms: hanging straight, horizontal sideways, forward.
    down = _pose(body_model, rest, {"arm_elev_l": 0.0, "elbow_flex_l": 0.0})
    arm = down[j["left_wrist"]] - down[j["left_shoulder"]]
    assert np.degrees(np.arccos(-arm[2] / np.linalg.norm(arm))) < 8.0
    side = _pose(body_model, rest, {"arm_elev_l": 90.0, "elbow_flex_l": 0.0})
    arm = side[j["left_wrist"]] - side[j["left_shoulder"]]
    assert arm[0] > 0.45 and abs(arm[2]) < 0.08
    point = _pose(body_model, rest, {"shoulder_flex_r": 90.0, "arm_elev_r": 0.0, "elbow_flex_r": 0.0})
    arm = point[j["right_wrist"]] - point[j["right_shoulder"]]
    assert arm[1] < -0.45 and abs(arm[2]) < 0.08
    # Yaw pi/2 + heading 0: the body faces +x.
    turned = _pose(body_model, rest, {}, yaw_rad=np.pi / 2)
    assert turned[j["nose"], 0] > turned[j["left_ear"], 0]


def test_crouch_keeps_the_soles_flat(body_model, rest):
    j = JOINT_INDEX
    crouch = _pose(body_model, rest, {"hip_flex_l": 100.0, "knee_flex_l": 125.0, "foot_pitch_l": 0.0})
    still = _pose(body_model, rest, {})
    tilt = lambda kp: kp[j["left_big_toe"], 2] - kp[j["left_heel"], 2]  # noqa: E731
    assert abs(tilt(crouch) - tilt(still)) < 0.02


def test_rotations_are_proper():
    R = axis_angle_to_rotmat(np.array([[0.0, 0.6, 0.8]]), np.array([1.1]))
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.eye(3)[None], atol=1e-12)
    assert np.linalg.det(R[0]) == pytest.approx(1.0)
    np.testing.assert_allclose(R[0] @ [0.0, 0.6, 0.8], [0.0, 0.6, 0.8], atol=1e-12)


def test_activity_plans_cover_the_frames():
    segments = plan_activities(900, 30.0, np.random.default_rng(0))
    assert segments[0].start == 0 and segments[-1].stop == 900
    assert all(a.stop == b.start for a, b in zip(segments, segments[1:]))
    assert all(a.kind != b.kind for a, b in zip(segments, segments[1:]))
    assert {s.kind for s in segments} <= set(ACTIVITIES)
    assert np.allclose(smooth(np.full(50, 2.5), 30.0), 2.5)


def test_motions_shapes_and_exact_keypoints(body_model, rest, motions):
    P, F, B = 4, 240, body_model.num_posed_bones
    assert motions.bone_rotmats_local.shape == (P, F, B, 3, 3)
    assert motions.root_translation_m.shape == (P, F, 3)
    R = motions.bone_rotmats_local
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-5)
    with torch.no_grad():
        kp = body_model.keypoints(
            rest,
            torch.as_tensor(R, dtype=body_model.dtype),
            torch.as_tensor(motions.root_translation_m, dtype=body_model.dtype),
        )
    np.testing.assert_allclose(kp.double().numpy(), motions.keypoints_world_m, atol=1e-6)


def test_feet_on_the_floor(motions):
    feet_z = motions.keypoints_world_m[..., [JOINT_INDEX[n] for n in FOOT_JOINTS], 2]
    lowest = feet_z.min(axis=-1)
    np.testing.assert_allclose(lowest, 0.0, atol=1e-4)
    # Nobody floats or sinks: the head stays at a human height while not crouching.
    standing = motions.activity != ACTIVITIES.index("crouch")
    head = motions.keypoints_world_m[..., JOINT_INDEX["nose"], 2]
    assert np.all(head[standing] > 1.2) and np.all(head < 1.95)


def test_people_stay_in_the_area_and_apart(motions):
    xy = motions.root_translation_m[..., :2]
    half = np.array(AREA_M) / 2
    assert np.all(np.abs(xy) <= half)
    distance = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    distance[np.arange(4), np.arange(4)] = np.inf
    assert distance.min() > 0.4


def test_walking_speed_and_heading(motions):
    xy = motions.root_translation_m[..., :2]
    velocity = np.diff(xy, axis=1) * 30.0
    speed = np.linalg.norm(velocity, axis=-1)
    assert speed.max() < 2.5
    walk = motions.activity == ACTIVITIES.index("walk")
    walking = walk[:, 1:] & walk[:, :-1]
    assert walking.sum() > 60
    assert 0.7 < speed[walking].mean() < 1.7
    # Walkers face where they go: heading within 30 degrees of the velocity direction most of the time.
    direction = np.arctan2(velocity[..., 1], velocity[..., 0])
    error = np.abs((direction - motions.heading_rad[:, 1:] + np.pi) % (2 * np.pi) - np.pi)
    fast = walking & (speed > 0.8)
    assert np.median(np.degrees(error[fast])) < 30.0
    # A gait cycle: the ankles alternate going up and down while walking.
    ankle_z = motions.keypoints_world_m[..., [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]], 2]
    lift = ankle_z.max(axis=-1)[:, 1:][walking]
    assert lift.max() > 0.15 and np.percentile(lift, 10) < 0.12
