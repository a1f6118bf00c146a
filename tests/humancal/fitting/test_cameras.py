"""Cameras as variables of the fit: the parametrisation, the joint refinement and the bundle adjustment."""

import numpy as np
import pytest
import roma
import torch

from evaluation.camera_metrics import camera_errors
from humancal.camera import Camera, CameraRig
from humancal.fitting import BodyFitConfig, CameraVariables, bundle_adjust, fit_bodies
from humancal.prior import shipped_prior
from tests.humancal.fitting.test_fit import FAST, scene_inputs  # noqa: F401  (the fixture)


def _perturbed(rig: CameraRig, seed: int = 1) -> CameraRig:
    """Every view's focal off by up to 4 %, orientation by about 1 degree, centre by about 10 cm."""
    rng = np.random.default_rng(seed)
    cameras = []
    for c in rig.to_cameras():
        K = c.K.copy()
        K[[0, 1], [0, 1]] *= 1.0 + rng.uniform(-0.04, 0.04)
        R = roma.rotvec_to_rotmat(torch.as_tensor(rng.normal(0, np.radians(1.0) / np.sqrt(3), 3))).numpy() @ \
            c.R_cam_from_world
        cameras.append(Camera.from_center(K, R, c.center_world_m + rng.normal(0, 0.06, 3), c.width_px, c.height_px))
    return CameraRig.from_cameras(cameras)


def _mean_errors(rig: CameraRig, truth: CameraRig) -> dict[str, float]:
    return {k: float(np.mean(v)) for k, v in camera_errors(rig.to_cameras(), truth.to_cameras()).items()
            if k != "alignment"}


def test_the_variables_start_at_the_rig_and_carry_gradients(scene_inputs):  # noqa: F811
    _, _, rig = scene_inputs
    cams = CameraVariables(rig, "int_ext")
    tensors = cams.tensors()
    np.testing.assert_allclose(tensors.K.detach().numpy(), rig.K)
    np.testing.assert_allclose(tensors.t_cam_from_world_m.detach().numpy(), rig.t_cam_from_world_m, atol=1e-12)
    np.testing.assert_allclose(cams.to_rig().R_cam_from_world, rig.R_cam_from_world, atol=1e-12)
    pixels, _, _ = tensors.project(torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64))
    pixels.sum().backward()
    assert all(v.grad is not None and torch.isfinite(v.grad).all() for v in cams.variables())
    assert len(CameraVariables(rig, "ext").variables()) == 2  # rotation and centre, focal held
    assert CameraVariables(rig, "fixed").variables() == []
    with_k1 = CameraVariables(rig, "int_ext", refine_k1=True)
    assert len(with_k1.variables()) == 4
    with torch.no_grad():
        with_k1.k1 += 0.01
    np.testing.assert_allclose(with_k1.to_rig().distortion[:, 0], rig.distortion[:, 0] + 0.01)
    with pytest.raises(ValueError, match="camera regime 'intrinsics' must be one of"):
        CameraVariables(rig, "intrinsics")
    with pytest.raises(ValueError, match=r"BodyFitConfig.cameras='intrinsics' must be one of \['fixed', 'ext', 'int_ext'\]"):
        BodyFitConfig(cameras="intrinsics")


def test_joint_refinement_brings_perturbed_cameras_back(body_model, scene_inputs):  # noqa: F811
    torch.manual_seed(0)
    _, observations, rig = scene_inputs
    start = _perturbed(rig)
    before = _mean_errors(start, rig)
    # the joint refinement by itself (no bundle-adjusted start)
    config = FAST.replace(cameras="int_ext", rounds=BodyFitConfig().rounds, bundle_start=False)
    fit = fit_bodies(body_model, observations, start, shipped_prior()[0], config)
    after = _mean_errors(fit.cameras, rig)
    # position and angle at least halve, the focal error drops (3 views, 40 frames: weakly observed)
    for name in ("position_error_mm", "angle_error_deg"):
        assert after[name] < 0.5 * before[name], (name, before, after)
    assert after["focal_error_pct"] < 0.8 * before["focal_error_pct"], (before, after)
    assert fit.stage_seconds["cameras"] > 0 and fit.stage_seconds["bundle"] == 0.0
    # the pipeline's schedule: a bundle adjustment first, then the same refinement
    scheduled = fit_bodies(body_model, observations, start, shipped_prior()[0], config.replace(bundle_start=True))
    assert scheduled.stage_seconds["bundle"] > 0
    after = _mean_errors(scheduled.cameras, rig)
    for name in ("position_error_mm", "angle_error_deg"):
        assert after[name] < 0.5 * before[name], (name, before, after)
    assert after["focal_error_pct"] < before["focal_error_pct"], (before, after)
    ext = fit_bodies(body_model, observations, start, shipped_prior()[0], config.replace(cameras="ext"))
    np.testing.assert_allclose(ext.cameras.K, start.K)  # focal known: held


def test_bundle_adjustment_on_triangulated_joints(scene_inputs):  # noqa: F811
    _, observations, rig = scene_inputs
    start = _perturbed(rig)
    result = bundle_adjust(observations, start, BodyFitConfig(), iterations=100)
    before, after = _mean_errors(start, rig), _mean_errors(result.cameras, rig)
    assert after["angle_error_deg"] < 0.5 * before["angle_error_deg"], (before, after)
    assert result.reprojection_error_px < 8.0
    assert np.isfinite(result.points_world_m[observations.joints_valid]).all()


def test_a_bundle_adjustment_that_fails_keeps_the_initial_cameras_and_says_so(body_model, scene_inputs):  # noqa: F811
    from dataclasses import replace

    _, observations, rig = scene_inputs
    start = _perturbed(rig)
    keypoints = observations.keypoints_px.copy()
    v, p, t, j = np.argwhere((observations.confidence > 0) & observations.joints_valid[None])[0]
    keypoints[v, p, t, j] = np.nan  # a non-finite objective from the first evaluation
    broken = replace(observations, keypoints_px=keypoints)
    result = bundle_adjust(broken, start, BodyFitConfig(), iterations=5)
    assert result.failure is not None and "the objective became nan" in result.failure
    np.testing.assert_allclose(result.cameras.K, start.K)
    np.testing.assert_allclose(result.cameras.t_cam_from_world_m, start.t_cam_from_world_m, atol=1e-12)
