"""Box normalisation of detections and the crop frame."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.keypoints import NUM_JOINTS
from humancal.lifter import R_crop_from_cam, normalize_detections, root_relative, rotate_crop_to_camera
from humancal.lifter.features import ROOT_JOINTS


def _detections(num: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    keypoints = rng.uniform([100.0, 50.0], [700.0, 900.0], (num, NUM_JOINTS, 2))
    scores = rng.uniform(0.2, 1.0, (num, NUM_JOINTS))
    scores[rng.random((num, NUM_JOINTS)) < 0.2] = 0.0
    keypoints[scores == 0] = np.nan
    return keypoints, scores


def test_inputs_lie_in_the_unit_box_and_missing_joints_are_zero():
    keypoints, scores = _detections(50, np.random.default_rng(0))
    out = normalize_detections(keypoints, scores)
    assert out.features.shape == (50, NUM_JOINTS, 3) and out.features.dtype == np.float32
    assert out.valid.all()
    xy = out.features[..., :2]
    assert np.abs(xy).max() <= 1.0 + 1e-6
    # The longer box side spans exactly [-1, 1].
    span = xy.max(axis=1) - np.where(scores[..., None] > 0, xy, np.inf).min(axis=1)
    np.testing.assert_allclose(span.max(axis=1), 2.0, atol=1e-5)
    missing = scores == 0
    assert (out.features[missing] == 0).all()
    np.testing.assert_allclose(out.features[..., 2], scores, atol=1e-7)


def test_inputs_are_invariant_to_image_scaling_and_shifting():
    """A different focal length, principal point or image size is a 2D similarity: the input does not change."""
    keypoints, scores = _detections(40, np.random.default_rng(1))
    base = normalize_detections(keypoints, scores)
    for scale, shift in ((2.5, (0.0, 0.0)), (0.4, (-300.0, 120.0)), (1.0, (1000.0, 7.0))):
        moved = normalize_detections(keypoints * scale + np.array(shift), scores)
        np.testing.assert_allclose(moved.features, base.features, atol=1e-5)
        np.testing.assert_allclose(moved.box_scale_px, base.box_scale_px * scale, rtol=1e-12)
    # ... but a genuine change of the pose changes it.
    bent = keypoints.copy()
    bent[:, 9] += 40.0
    assert not np.allclose(normalize_detections(bent, scores).features, base.features, atol=1e-3)


def test_too_few_joints_make_a_detection_invalid():
    keypoints, scores = _detections(3, np.random.default_rng(2))
    scores[0, 3:] = 0.0  # 3 joints
    scores[1, 4:] = 0.0  # 4 joints
    scores[1, :4] = 0.9
    keypoints[1, :4] = [[10.0, 10.0], [30.0, 80.0], [20.0, 40.0], [15.0, 60.0]]
    keypoints[2] = 250.0  # every joint at one pixel: no box
    out = normalize_detections(keypoints, scores, min_joints=4)
    assert out.valid.tolist() == [False, True, False]
    assert (out.features[0] == 0).all() and np.isnan(out.box_centre_px[0]).all()
    assert np.isfinite(out.box_centre_px[1]).all()


@pytest.mark.parametrize(
    ("keypoints_shape", "scores_shape", "message"),
    [
        ((5, 17, 2), (5, 17), r"keypoints_px must have shape \(D, 23, 2\), got \(5, 17, 2\)"),
        ((5, 23, 3), (5, 23), r"keypoints_px must have shape"),
        ((5, 23, 2), (4, 23), r"scores must have shape \(5, 23\)"),
        ((23, 2), (23,), r"keypoints_px must have shape"),
    ],
)
def test_wrong_shapes_are_rejected(keypoints_shape, scores_shape, message):
    with pytest.raises(ValueError, match=message):
        normalize_detections(np.zeros(keypoints_shape), np.ones(scores_shape))


def test_bad_values_are_rejected():
    keypoints, scores = _detections(4, np.random.default_rng(3))
    scores[1, 5] = 0.7
    keypoints[1, 5] = np.nan
    with pytest.raises(ValueError, match=r"non-finite positions .* \(first: detection 1, joint 5\)"):
        normalize_detections(keypoints, scores)
    keypoints[1, 5] = 10.0
    bad = scores.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="scores must be finite"):
        normalize_detections(keypoints, bad)
    bad[0, 0] = 1.5
    with pytest.raises(ValueError, match=r"scores must lie in \[0, 1\]"):
        normalize_detections(keypoints, bad)
    with pytest.raises(ValueError, match="min_joints=1 must be >= 2"):
        normalize_detections(keypoints, scores, min_joints=1)


def test_crop_rotation_brings_the_box_centre_ray_onto_the_optical_axis():
    K = np.array([[1200.0, 0.0, 960.0], [0.0, 1200.0, 540.0], [0.0, 0.0, 1.0]])
    centres = np.array([[960.0, 540.0], [0.0, 0.0], [1919.0, 300.0], [-200.0, 1500.0]])
    R = R_crop_from_cam(centres, K)
    np.testing.assert_allclose(R[0], np.eye(3), atol=1e-12)  # the image centre: no turn
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    rays = np.linalg.solve(K, np.c_[centres, np.ones(4)].T).T
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", R, rays), np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-12)
    # The smallest such rotation: its axis is perpendicular to the optical axis (no roll about z).
    angle = np.degrees(np.arccos(rays[:, 2]))
    rotation_deg = np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    np.testing.assert_allclose(rotation_deg, angle, atol=1e-6)


def test_rotate_crop_to_camera_undoes_the_crop_rotation():
    rng = np.random.default_rng(4)
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    centres = rng.uniform(0, 640, (6, 2))
    joints_cam = root_relative(rng.normal(size=(6, NUM_JOINTS, 3)))
    R = R_crop_from_cam(centres, K)
    joints_crop = np.einsum("nij,nkj->nki", R, joints_cam)
    np.testing.assert_allclose(rotate_crop_to_camera(joints_crop, centres, K), joints_cam, atol=1e-12)
    np.testing.assert_allclose(joints_cam[:, list(ROOT_JOINTS)].mean(axis=1), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\) or \(6, 3, 3\)"):
        rotate_crop_to_camera(joints_crop, centres, np.eye(4))
    with pytest.raises(ValueError, match="box_centre_px has 5 rows but joints_crop_m has 6"):
        rotate_crop_to_camera(joints_crop, centres[:5], K)
