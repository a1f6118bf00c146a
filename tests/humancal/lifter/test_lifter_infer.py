"""Inference: shapes, batch independence, crop and camera frames, input checks."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.keypoints import NUM_JOINTS
from humancal.lifter import (
    LifterConfig,
    LifterNet,
    SampleConfig,
    evaluate_lifter,
    evaluate_predictions,
    lift_detections,
    load_lifter,
    rotate_crop_to_camera,
    synthesize_samples,
)
from humancal.lifter.features import ROOT_JOINTS
from humancal.lifter.infer import lift_features


@pytest.fixture(scope="module")
def lifter(tiny_training):
    return load_lifter(tiny_training[0])


@pytest.fixture(scope="module")
def samples(train_val_clips):
    return synthesize_samples(train_val_clips[1], 300, SampleConfig(), np.random.default_rng(11))


def test_lifted_poses_have_the_documented_shapes(lifter, samples):
    lifted = lift_detections(lifter, samples.keypoints_px, samples.scores)
    assert len(lifted) == 300 and lifted.frame == "crop"
    assert lifted.joints_cam_m.shape == (300, NUM_JOINTS, 3) and lifted.height_m.shape == (300,)
    assert lifted.upright_score.shape == (300,) and lifted.valid.all()
    np.testing.assert_allclose(lifted.joints_cam_m[:, list(ROOT_JOINTS)].mean(axis=1), 0.0, atol=1e-6)
    assert ((lifted.upright_score >= 0) & (lifted.upright_score <= 1)).all()
    assert 1.4 < np.median(lifted.height_m) < 2.0 and (lifted.height_m > 0.5).all()
    np.testing.assert_allclose(lifted.box_centre_px, samples.box_centre_px, atol=1e-3)
    empty = lift_detections(lifter, np.zeros((0, NUM_JOINTS, 2)), np.zeros((0, NUM_JOINTS)))
    assert empty.joints_cam_m.shape == (0, NUM_JOINTS, 3) and empty.valid.shape == (0,)


def test_results_do_not_depend_on_the_batch(lifter, samples):
    full = lift_detections(lifter, samples.keypoints_px, samples.scores, batch_size=4096)
    one_by_one = lift_detections(lifter, samples.keypoints_px, samples.scores, batch_size=1)
    np.testing.assert_allclose(one_by_one.joints_cam_m, full.joints_cam_m, atol=1e-5)
    rows = np.array([7, 3, 250])
    subset = lift_detections(lifter, samples.keypoints_px[rows], samples.scores[rows])
    np.testing.assert_allclose(subset.joints_cam_m, full.joints_cam_m[rows], atol=1e-5)


def test_detections_with_too_few_joints_are_marked_not_lifted(lifter, samples):
    keypoints, scores = samples.keypoints_px[:5].copy(), samples.scores[:5].copy()
    keep = np.flatnonzero(scores[2] > 0)[:3]
    scores[2] = 0.0
    scores[2, keep] = 0.9
    keypoints[2, scores[2] == 0] = np.nan
    lifted = lift_detections(lifter, keypoints, scores)
    assert lifted.valid.tolist() == [True, True, False, True, True]
    assert np.isnan(lifted.joints_cam_m[2]).all() and np.isnan(lifted.height_m[2]) and np.isnan(lifted.upright_score[2])
    reference = lift_detections(lifter, samples.keypoints_px[:5], samples.scores[:5])
    np.testing.assert_allclose(lifted.joints_cam_m[[0, 1, 3, 4]], reference.joints_cam_m[[0, 1, 3, 4]], atol=1e-6)


def test_intrinsics_turn_the_poses_into_the_camera_frame(lifter, samples):
    crop = lift_detections(lifter, samples.keypoints_px, samples.scores)
    camera = lift_detections(lifter, samples.keypoints_px, samples.scores, K=samples.K)
    assert camera.frame == "camera"
    expected = rotate_crop_to_camera(crop.joints_cam_m, crop.box_centre_px, samples.K)
    np.testing.assert_allclose(camera.joints_cam_m, expected, atol=1e-9)
    np.testing.assert_allclose(crop.in_camera_frame(samples.K).joints_cam_m, expected, atol=1e-9)
    np.testing.assert_allclose(camera.height_m, crop.height_m, atol=1e-9)  # a rotation keeps lengths
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\) or \(300, 3, 3\)"):
        crop.in_camera_frame(samples.K[:10])


def test_bad_inputs_give_clear_errors(lifter, samples):
    keypoints, scores = samples.keypoints_px[:4].copy(), samples.scores[:4].copy()
    with pytest.raises(ValueError, match=r"keypoints_px must have shape \(D, 23, 2\), got \(4, 23, 3\)"):
        lift_detections(lifter, np.zeros((4, NUM_JOINTS, 3)), scores)
    with pytest.raises(ValueError, match=r"scores must have shape \(4, 23\)"):
        lift_detections(lifter, keypoints, scores[:, :17])
    seen = np.argwhere(scores > 0)[0]
    broken = keypoints.copy()
    broken[tuple(seen)] = np.nan
    with pytest.raises(ValueError, match="non-finite positions for 1 joint"):
        lift_detections(lifter, broken, scores)
    nan_scores = scores.copy()
    nan_scores[0, 0] = np.nan
    with pytest.raises(ValueError, match="scores must be finite"):
        lift_detections(lifter, keypoints, nan_scores)
    with pytest.raises(ValueError, match="batch_size=0 must be >= 1"):
        lift_detections(lifter, keypoints, scores, batch_size=0)


def test_load_lifter_rejects_foreign_checkpoints(tiny_training):
    checkpoint = tiny_training[0]
    with pytest.raises(ValueError, match="not a lifter checkpoint"):
        load_lifter({"state_dict": checkpoint["state_dict"]})
    wider = dict(checkpoint, config=LifterConfig.tiny().replace(width=128).to_dict())
    with pytest.raises(ValueError, match="weights do not fit its config"):
        load_lifter(wider)


def test_evaluation_through_inference_matches_the_network(lifter, samples):
    metrics = evaluate_lifter(lifter, samples)
    direct = evaluate_predictions(lift_features(lifter.net, samples.features), samples)
    for key in ("mpjpe_mm", "pa_mpjpe_mm", "mpjpe_no_intrinsics_mm"):
        assert metrics[key] == pytest.approx(direct[key], abs=0.5)
    assert metrics["pa_mpjpe_mm"] < metrics["mpjpe_mm"]
    # An untrained network is much worse.
    untrained = evaluate_predictions(lift_features(LifterNet(64, 1, 0.0), samples.features), samples)
    assert untrained["mpjpe_mm"] > metrics["mpjpe_mm"] + 100.0


def test_the_network_output_is_root_relative():
    net = LifterNet(32, 2, 0.0)
    out = lift_features(net, np.random.default_rng(0).uniform(-1, 1, (5, NUM_JOINTS, 3)).astype(np.float32))
    np.testing.assert_allclose(out[:, list(ROOT_JOINTS)].mean(axis=1), 0.0, atol=1e-6)
    import torch

    with pytest.raises(ValueError, match=r"features must have shape \(B, 23, 3\), got \(5, 69\)"):
        net(torch.zeros(5, 69))


def test_mirror_averaging_makes_lifting_mirror_equivariant(lifter, samples):
    """Lifting the mirrored image gives exactly the mirrored pose (and differs from a single pass)."""
    from humancal.keypoints import FLIP_INDEX

    flip = list(FLIP_INDEX)
    mirrored = samples.features[:, flip].copy()
    mirrored[..., 0] *= -1
    pose = lift_features(lifter.net, samples.features)
    pose_of_mirror = lift_features(lifter.net, mirrored)[:, flip]
    pose_of_mirror[..., 0] *= -1
    np.testing.assert_allclose(pose_of_mirror, pose, atol=1e-5)
    single = lift_features(lifter.net, samples.features, mirror_average=False)
    assert np.abs(single - pose).max() > 1e-3
