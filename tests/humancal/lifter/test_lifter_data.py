"""Training-sample synthesis: virtual cameras, detector noise, inputs and targets."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from humancal.camera import Camera, project_points
from humancal.keypoints import FLIP_INDEX, NUM_JOINTS, joint_indices
from humancal.lifter import (
    SampleConfig,
    VirtualCameraRanges,
    normalize_detections,
    sample_virtual_cameras,
    synthesize_samples,
)
from humancal.lifter.cameras import focal_limits_px
from humancal.lifter.features import ROOT_JOINTS
from humancal.synthetic import DetectorNoise, simulate_detections

_LIMB_PAIRS = [joint_indices(pair) for pair in (["left_knee", "left_ankle"], ["right_hip", "right_knee"])]


def test_samples_have_the_documented_shapes_and_count(motion_clips):
    samples = synthesize_samples(motion_clips, 700, SampleConfig(), np.random.default_rng(0))
    assert len(samples) == 700
    assert samples.features.shape == (700, NUM_JOINTS, 3) and samples.features.dtype == np.float32
    assert samples.targets_m.shape == (700, NUM_JOINTS, 3) and samples.targets_m.dtype == np.float32
    assert samples.keypoints_px.shape == (700, NUM_JOINTS, 2) and samples.scores.shape == (700, NUM_JOINTS)
    assert samples.K.shape == (700, 3, 3) and samples.R_crop_from_cam.shape == (700, 3, 3)
    assert np.isfinite(samples.features).all() and np.isfinite(samples.targets_m).all()
    np.testing.assert_allclose(samples.targets_m[:, list(ROOT_JOINTS)].mean(axis=1), 0.0, atol=1e-6)
    assert ((samples.scores > 0).sum(axis=1) >= SampleConfig().min_joints).all()
    # Missing joints: NaN pixels, zero score, zero input.
    missing = samples.scores == 0
    assert missing.any() and np.isnan(samples.keypoints_px[missing]).all() and (samples.features[missing] == 0).all()
    # Virtual cameras span the documented focal range; the person lands anywhere in the image.
    focal = samples.K[:, 0, 0]
    assert focal.min() >= 500.0 and focal.max() <= 2500.0 and focal.max() - focal.min() > 800.0
    # Every group mixes frames of all clips.
    assert len(np.unique(samples.clip_index)) == len(motion_clips)
    heights = {c: h for c, h in zip(samples.clip_index, samples.height_m)}
    assert len(set(np.round(list(heights.values()), 6))) == len(motion_clips)
    # A few percent of the detections are left-right flipped (training noise: 3 %).
    assert 0.0 < samples.flipped.mean() < 0.1


def test_targets_project_onto_the_detections_with_a_perfect_detector(motion_clips):
    """root + R_cam_from_crop @ target, projected with K, gives back the detected pixels exactly."""
    config = SampleConfig(noise=DetectorNoise.none(), score_scale_range=(1.0, 1.0))
    samples = synthesize_samples(motion_clips, 400, config, np.random.default_rng(1))
    joints_cam = samples.root_cam_m[:, None, :] + samples.targets_cam_m
    projected = np.einsum("nij,nkj->nki", samples.K, joints_cam)
    pixels = projected[..., :2] / projected[..., 2:]
    seen = samples.scores > 0
    np.testing.assert_allclose(pixels[seen], samples.keypoints_px[seen], atol=1e-2)
    assert not samples.flipped.any()
    # Bone lengths in the target equal those of the 3D motion (rotations and mirroring keep lengths).
    for a, b in _LIMB_PAIRS:
        length = np.linalg.norm(samples.targets_m[:, a] - samples.targets_m[:, b], axis=-1)
        assert 0.3 < length.min() and length.max() < 0.6


def test_flipped_detections_get_the_flipped_3d_pose(motion_clips):
    """Every lifted joint corresponds to the 2D joint of the same label, also for left-right flips."""
    noise = replace(DetectorNoise.none(), flip_rate=0.5)
    config = SampleConfig(noise=noise, score_scale_range=(1.0, 1.0))
    samples = synthesize_samples(motion_clips, 400, config, np.random.default_rng(2))
    assert 0.3 < samples.flipped.mean() < 0.7
    joints_cam = samples.root_cam_m[:, None, :] + samples.targets_cam_m
    projected = np.einsum("nij,nkj->nki", samples.K, joints_cam)
    pixels = projected[..., :2] / projected[..., 2:]
    seen = samples.scores > 0
    np.testing.assert_allclose(pixels[seen], samples.keypoints_px[seen], atol=1e-2)
    # The flip really swapped labels: left joints of flipped samples lie where the right ones would be.
    flipped = samples.flipped
    swapped = samples.targets_m[flipped][:, list(FLIP_INDEX)]
    assert not np.allclose(swapped, samples.targets_m[flipped], atol=1e-3)


def test_scaling_the_focal_length_changes_nothing_in_the_input(motion_clips):
    """Same scene, cameras that differ only by focal length and image size (scaled together): same inputs."""
    world = motion_clips[0][1][::10][None]
    height = np.array([1.75])
    base = sample_virtual_cameras(3, 1.75, 0.95, VirtualCameraRanges(), np.random.default_rng(3))
    features = []
    for scale in (1.0, 1.7):
        cameras = []
        for cam in base:
            K = cam.K.copy()
            K[:2] *= scale
            size = (round(cam.width_px * scale), round(cam.height_px * scale))
            K[0, 2], K[1, 2] = size[0] / 2, size[1] / 2
            cameras.append(Camera(K, cam.R_cam_from_world, cam.t_cam_from_world_m, *size))
        out = simulate_detections(world, height, cameras, DetectorNoise(), np.random.default_rng(4))
        keypoints = np.where(out.present[..., None], out.keypoints_px, np.nan)
        features.append(normalize_detections(keypoints, out.scores).features)
    assert features[0].shape == features[1].shape and len(features[0]) > 5
    np.testing.assert_allclose(features[1], features[0], atol=2e-3)


def test_virtual_cameras_look_like_real_rigs():
    ranges = VirtualCameraRanges()
    cameras = sample_virtual_cameras(300, 1.75, 0.95, ranges, np.random.default_rng(5))
    heights = np.array([c.center_world_m[2] for c in cameras])
    distances = np.array([np.hypot(*c.center_world_m[:2]) for c in cameras])
    pitch_deg = np.degrees(np.arctan2(heights - 0.95, distances))
    line_of_sight = np.hypot(distances, heights - 0.95)
    ordinary = (heights >= 0.5) & (heights <= 4.0) & (distances >= 2.0) & (distances <= 10.0)
    steep = ((pitch_deg >= 30.0 - 1e-6) & (pitch_deg <= 75.0 + 1e-6) & (line_of_sight >= 2.0 - 1e-9)
             & (line_of_sight <= 10.0 + 1e-9))  # the distance along the line of sight
    assert np.all(ordinary | steep) and (~ordinary).any()
    assert 0.1 < (pitch_deg >= 45.0).mean() < ranges.steep_fraction  # a share of ceiling-like cameras
    pelvis_px = []
    for cam in cameras:
        R = cam.R_cam_from_world
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        assert (cam.width_px, cam.height_px) in ranges.image_sizes_px
        fov = np.degrees(2 * np.arctan(cam.width_px / (2 * cam.K[0, 0])))
        assert 30.0 - 1e-6 <= fov <= 100.0 + 1e-6
        pixel, depth = project_points(cam, np.array([0.0, 0.0, 0.95]))
        assert depth > 0
        pelvis_px.append(pixel / [cam.width_px, cam.height_px])
        # World up is image up (small roll): a point above the pelvis is higher in the image.
        above, _ = project_points(cam, np.array([0.0, 0.0, 1.45]))
        assert above[1] < pixel[1]
    pelvis_px = np.array(pelvis_px)
    assert pelvis_px.min() >= -0.1 - 1e-9 and pelvis_px.max() <= 1.1 + 1e-9
    assert (pelvis_px < 0.15).any() and (pelvis_px > 0.85).any()  # anywhere in view
    outside = ((pelvis_px < 0) | (pelvis_px > 1)).any(axis=1).mean()
    assert 0.0 < outside < ranges.truncation_prob  # a few people are partly outside the image


def test_most_detections_show_most_of_the_body(motion_clips):
    """Like real rigs (and the synthetic scenes): most detections are nearly complete, few are truncated."""
    samples = synthesize_samples(motion_clips, 2000, SampleConfig(), np.random.default_rng(6))
    joints = (samples.scores > 0).sum(axis=1)
    assert 0.5 < (joints >= 20).mean() < 0.9
    assert 0.01 < (joints < 12).mean() < 0.2


def test_focal_limits_follow_the_field_of_view():
    ranges = VirtualCameraRanges()
    low, high = focal_limits_px(640, ranges)
    assert low == 500.0 and high == pytest.approx(320.0 / np.tan(np.radians(15.0)))
    with pytest.raises(ValueError, match="no focal length"):
        focal_limits_px(640, VirtualCameraRanges(horizontal_fov_range_deg=(5.0, 6.0), focal_range_px=(500.0, 600.0)))


def test_synthesis_is_deterministic_and_seed_dependent(motion_clips):
    config = SampleConfig()
    a = synthesize_samples(motion_clips, 300, config, np.random.default_rng(9))
    b = synthesize_samples(motion_clips, 300, config, np.random.default_rng(9))
    c = synthesize_samples(motion_clips, 300, config, np.random.default_rng(10))
    np.testing.assert_array_equal(a.features, b.features)
    np.testing.assert_array_equal(a.targets_m, b.targets_m)
    assert not np.array_equal(a.targets_m, c.targets_m)


def test_bad_clips_are_rejected(motion_clips):
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="clips must be a non-empty sequence"):
        synthesize_samples([], 10, SampleConfig(), rng)
    with pytest.raises(ValueError, match=r"clips\[0\] keypoints_world_m must have shape \(F >= 1, 23, 3\), got"):
        synthesize_samples([("s", np.zeros((5, 17, 3)))], 10, SampleConfig(), rng)
    nan_clip = motion_clips[0][1].copy()
    nan_clip[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match=r"clips\[0\] \(subject 'p0'\) has non-finite keypoints"):
        synthesize_samples([("p0", nan_clip)], 10, SampleConfig(), rng)
    with pytest.raises(ValueError, match=r"must be a \(subject: str, keypoints_world_m\) pair"):
        synthesize_samples([motion_clips[0][1]], 10, SampleConfig(), rng)
    with pytest.raises(ValueError, match="num_samples=0 must be >= 1"):
        synthesize_samples(motion_clips, 0, SampleConfig(), rng)


def test_subset_keeps_rows_aligned(motion_clips):
    samples = synthesize_samples(motion_clips, 50, SampleConfig(), np.random.default_rng(12))
    rows = np.array([4, 0, 31])
    part = samples.subset(rows)
    assert len(part) == 3
    np.testing.assert_array_equal(part.targets_m, samples.targets_m[rows])
    np.testing.assert_array_equal(part.K, samples.K[rows])
    assert len(samples.subset(samples.flipped)) == int(samples.flipped.sum())
