"""Standing height and upright score from a 3D pose, on real anny bodies."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from humancal.keypoints import NUM_JOINTS
from humancal.lifter import height_from_pose_m, upright_score
from humancal.camera import look_at
from humancal.synthetic import sample_people
from humancal.synthetic.poses import CHANNEL_INDEX, CHANNELS, arm_geometry, channels_to_rotmats

HEIGHT_TOLERANCE_M = 0.025
"""Largest error of height_from_pose_m on anny bodies standing in the identity pose (measured: 16 mm)."""


@pytest.fixture(scope="module")
def people(body_model):
    # Other bodies than the 1,000 the constants were fitted on (seed 0).
    return sample_people(body_model, 40, np.random.default_rng(2024), height_range_m=(1.4, 2.0))


@pytest.fixture(scope="module")
def rest(body_model, people):
    return body_model.rest_skeleton(torch.as_tensor(people.phenotypes, dtype=body_model.dtype))


def _posed(body_model, rest, channels: dict[str, float]) -> np.ndarray:
    """(P, 23, 3) world keypoints of every person in one joint-angle pose, feet near the floor."""
    values = np.zeros((1, len(CHANNELS)))
    for name, value in channels.items():
        values[0, CHANNEL_INDEX[name]] = value
    out = []
    for p in range(rest.num_people):
        geometry = arm_geometry(rest.bone_heads_m[p].double().numpy(), body_model.posed_bones)
        rotmats = channels_to_rotmats(values, np.zeros(1), geometry, body_model.posed_bones)
        out.append(rotmats)
    rotmats = torch.as_tensor(np.stack(out), dtype=body_model.dtype)
    with torch.no_grad():
        kp = body_model.keypoints(rest, rotmats, torch.zeros(rest.num_people, 1, 3))[:, 0].double().numpy()
    kp[..., 2] -= kp[..., 2].min(axis=1, keepdims=True)
    return kp


def _in_camera(world: np.ndarray, camera_height_m: float = 2.5, distance_m: float = 4.0) -> np.ndarray:
    """World poses as seen by a camera looking at the pelvis from the front-left, pitched down."""
    centre = np.array([distance_m * np.cos(-1.0), distance_m * np.sin(-1.0), camera_height_m])
    R = look_at(centre, np.array([0.0, 0.0, 0.9]))
    return (world - centre) @ R.T


def test_height_from_pose_matches_the_body_model_height(body_model, rest, people):
    standing = _posed(body_model, rest, {})
    estimate = height_from_pose_m(standing)
    error = estimate - people.height_m
    assert np.abs(error).max() < HEIGHT_TOLERANCE_M
    assert abs(error.mean()) < 0.01
    # Any frame: a rotated, shifted pose has the same height.
    turned = standing @ np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]]).T + 3.0
    np.testing.assert_allclose(height_from_pose_m(turned), estimate, atol=1e-12)


def test_height_from_pose_holds_in_a_walking_pose(body_model, rest, people):
    stride = {"hip_flex_l": 25.0, "hip_flex_r": -15.0, "knee_flex_l": 20.0, "knee_flex_r": 10.0}
    error = height_from_pose_m(_posed(body_model, rest, stride)) - people.height_m
    assert np.abs(error).max() < 0.04


def test_upright_score_is_high_for_standing_and_low_for_crouching_or_lying(body_model, rest):
    standing = _posed(body_model, rest, {"arm_elev_l": 10.0, "arm_elev_r": 10.0})
    deep = {"hip_flex_l": 100.0, "hip_flex_r": 100.0, "knee_flex_l": 120.0, "knee_flex_r": 120.0, "spine_lean": 20.0}
    crouching = _posed(body_model, rest, deep)
    bowing = _posed(body_model, rest, {"spine_lean": 60.0})
    one_leg = _posed(body_model, rest, {"hip_flex_l": 45.0, "knee_flex_l": 70.0})
    lying = standing @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]).T  # turned onto its back
    lying_sideways = standing @ np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]).T
    for camera_height in (1.0, 2.5, 4.0):
        assert upright_score(_in_camera(standing, camera_height)).min() > 0.9
    assert upright_score(_in_camera(crouching)).max() < 0.05
    assert upright_score(_in_camera(bowing)).max() < 0.05
    assert upright_score(_in_camera(one_leg)).max() < 0.05
    assert upright_score(_in_camera(lying)).max() < 0.05
    assert upright_score(_in_camera(lying_sideways)).max() < 0.05
    # A camera rolled by 30 degrees sees the body leaning sideways in its image.
    roll = np.radians(30.0)
    R_roll = np.array([[np.cos(roll), -np.sin(roll), 0], [np.sin(roll), np.cos(roll), 0], [0, 0, 1]])
    rolled = _in_camera(standing) @ R_roll.T
    assert upright_score(rolled).max() < 0.05


def test_pose_cues_reject_bad_shapes_and_propagate_nan():
    with pytest.raises(ValueError, match=r"joints_m must have shape \(D, 23, 3\), got \(4, 17, 3\)"):
        height_from_pose_m(np.zeros((4, 17, 3)))
    with pytest.raises(ValueError, match=r"joints_cam_m must have shape \(D, 23, 3\), got \(23, 3\)"):
        upright_score(np.zeros((NUM_JOINTS, 3)))
    joints = np.random.default_rng(0).normal(size=(3, NUM_JOINTS, 3))
    joints[1] = np.nan
    assert np.isnan(height_from_pose_m(joints)[1]) and np.isfinite(height_from_pose_m(joints)[[0, 2]]).all()
    scores = upright_score(joints)
    assert np.isnan(scores[1]) and ((scores[[0, 2]] >= 0) & (scores[[0, 2]] <= 1)).all()
