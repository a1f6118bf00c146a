"""The self-calibration floor: the best rig under a convention, from exact projections of known points."""

import numpy as np
import pytest

from evaluation.calibration_floor import self_calibration_floor
from evaluation.camera_metrics import camera_errors
from humancal.camera import Camera, CameraRig, project_points
from humancal.fitting import BodyFitConfig
from humancal.fitting.joint_bundle import bundle_adjust_on_joints
from humancal.fitting.observations import BodyObservations
from tests.evaluation.test_camera_metrics import _rig


def _with_intrinsics(cams, change):
    return [Camera(change(c.K.copy()), c.R_cam_from_world, c.t_cam_from_world_m, c.width_px, c.height_px) for c in cams]


def test_self_calibration_floor_sees_an_off_centre_principal_point_as_a_turn():
    points = np.random.default_rng(3).uniform([-1.5, -1.5, 0.0], [1.5, 1.5, 1.8], size=(300, 3))
    offset = np.array([40.0, -25.0])

    def shifted(K):
        K[:2, 2] += offset
        return K

    moved = _with_intrinsics(_rig(4), shifted)
    floor = self_calibration_floor(moved, points)
    focal = np.array([c.K[0, 0] for c in moved])
    # The whole rig refitted with centred principal points: every camera turns by about the angle the offset
    # subtends, the centres and focal lengths move, and the images show it by about a pixel only.
    np.testing.assert_allclose(floor["angle_error_deg"], np.degrees(np.arctan(np.hypot(*offset) / focal)), rtol=0.15)
    assert (floor["position_error_mm"] > 5).all() and (floor["residual_px"] < 2.0).all()
    assert len(floor["cameras"]) == 4 and np.allclose([c.K[:2, 2] for c in floor["cameras"]], [640, 360])

    # With the true principal points allowed, nothing is left.
    exact = self_calibration_floor(moved, points, centred_principal_point=False)
    for key in ("focal_error_pct", "position_error_mm", "angle_error_deg", "residual_px"):
        np.testing.assert_allclose(exact[key], 0.0, atol=1e-3)


def test_self_calibration_floor_of_non_square_pixels_is_a_focal_error():
    points = np.random.default_rng(4).uniform([-1.5, -1.5, 0.0], [1.5, 1.5, 1.8], size=(300, 3))

    def stretched(K):
        K[0, 0] *= 1.04
        return K

    rig = _with_intrinsics(_rig(4), stretched)
    floor = self_calibration_floor(rig, points)
    assert (floor["focal_error_pct"] > 0.5).all() and (floor["angle_error_deg"] < 1.0).all()
    assert floor["focal_error_pct"].mean() > 1.0
    free = self_calibration_floor(rig, points, square_pixels=False)
    np.testing.assert_allclose(free["focal_error_pct"], 0.0, atol=1e-3)
    with pytest.raises(ValueError, match="at least 2 cameras and 6 finite points"):
        self_calibration_floor(rig, points[:5])


def test_self_calibration_floor_with_a_free_k1_fits_at_least_as_well():
    points = np.random.default_rng(5).uniform([-1.5, -1.5, 0.0], [1.5, 1.5, 1.8], size=(300, 3))

    def shifted(K):
        K[:2, 2] += (30.0, 20.0)
        return K

    rig = _with_intrinsics(_rig(4), shifted)
    without = self_calibration_floor(rig, points)
    with_k1 = self_calibration_floor(rig, points, free_k1=True)
    # One more parameter per view: the residual left does not rise, and the k1 is used.
    assert with_k1["residual_px"].mean() <= without["residual_px"].mean() + 1e-6
    assert np.abs([c.distortion[0] for c in with_k1["cameras"]]).max() > 1e-4
    assert all(c.distortion[0] == 0 for c in without["cameras"])



def _exact_observations(cameras, points):
    """The points as one "person" of 23 joints per frame, seen exactly by every camera (where in its image)."""
    frames = int(np.ceil(len(points) / 23))
    pad = frames * 23 - len(points)
    joints = np.concatenate([points, np.zeros((pad, 3))]).reshape(1, frames, 23, 3)
    valid = np.r_[np.ones(len(points), bool), np.zeros(pad, bool)].reshape(1, frames, 23)
    keypoints, confidence = np.zeros((len(cameras), 1, frames, 23, 2)), np.zeros((len(cameras), 1, frames, 23))
    for v, cam in enumerate(cameras):
        px, depth = project_points(cam, joints.reshape(-1, 3))
        seen = valid.reshape(-1) & (depth > 0) & (px >= 0).all(-1) & (px < [cam.width_px, cam.height_px]).all(-1)
        keypoints[v, 0] = np.where(seen[:, None], px, 0.0).reshape(frames, 23, 2)
        confidence[v, 0] = seen.reshape(frames, 23)
    return BodyObservations(np.array([0]), np.arange(frames), keypoints, confidence, joints, valid,
                            np.ones((1, frames), bool))


def test_self_calibration_floor_is_where_the_pipelines_own_bundle_adjustment_lands():
    # The body fit's bundle adjustment (Levenberg-Marquardt, centred principal points, one focal per view) on the
    # same exact projections, started at the true cameras moved to the convention, ends at the same cameras.
    points = np.random.default_rng(6).uniform([-1.5, -1.5, 0.0], [1.5, 1.5, 1.8], size=(300, 3))

    def shifted(K):
        K[:2, 2] += (35.0, -20.0)
        return K

    truth = _with_intrinsics(_rig(4), shifted)
    floor = self_calibration_floor(truth, points)
    start = []
    for cam in truth:
        K = cam.K.copy()
        K[:2, 2] = (cam.width_px / 2.0, cam.height_px / 2.0)
        start.append(Camera(K, cam.R_cam_from_world, cam.t_cam_from_world_m, cam.width_px, cam.height_px))
    result = bundle_adjust_on_joints(_exact_observations(truth, points), CameraRig.from_cameras(start),
                           BodyFitConfig(weight_camera_prior=1e-8, bundle_solver="lm", bundle_max_frames=10**6),
                           regime="int_ext", iterations=200)
    pipeline = camera_errors(result.cameras.to_cameras(), truth)
    assert floor["angle_error_deg"].mean() > 1.0  # a real floor, not the truth
    for key, tolerance in (("focal_error_pct", 0.05), ("position_error_mm", 1.0), ("angle_error_deg", 0.01)):
        np.testing.assert_allclose(pipeline[key], floor[key], atol=tolerance)
