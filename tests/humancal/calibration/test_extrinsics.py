"""End-to-end camera initialisation on synthetic scenes (stand-in lifted poses) and its failure modes."""

import numpy as np
import pytest

from evaluation.camera_metrics import camera_errors
from humancal.calibration import (
    CalibrationError,
    ExtrinsicsConfig,
    IntrinsicsConfig,
    LiftedPoses,
    estimate_extrinsics,
    estimate_intrinsics,
)
from humancal.tables.detections import DenseDetections


def _calibrate(dets, lifted, cameras, intrinsics_config=None, config=None):
    sizes = [(c.width_px, c.height_px) for c in cameras]
    intr = estimate_intrinsics(dets, lifted, sizes, intrinsics_config)
    return intr, estimate_extrinsics(dets, lifted, intr, config)


@pytest.fixture(scope="module")
def ring_result(ring_scene, ring_stand_in):
    # The stand-in poses have the people's true sizes (no lifter has): the world's scale is tested as the bundle
    # adjustment takes it from them, not as the reference adult's limbs set it (tests/.../test_world_scale.py).
    return _calibrate(ring_stand_in.detections, ring_stand_in.lifted, list(ring_scene.rig),
                      config=ExtrinsicsConfig(scale_from_limbs=False))


def test_ring_rig_is_recovered(ring_scene, ring_result):
    _, result = ring_result
    err = camera_errors(result.cameras, list(ring_scene.rig))
    assert np.all(err["focal_error_pct"] < 3.0), err["focal_error_pct"]
    assert np.all(err["angle_error_deg"] < 1.0), err["angle_error_deg"]
    assert np.all(err["position_error_mm"] < 100.0), err["position_error_mm"]
    assert abs(err["alignment"].scale - 1) < 0.03  # metric scale from the body size


def test_world_is_z_up_with_the_floor_at_zero(ring_scene, ring_result):
    _, result = ring_result
    for est, gt in zip(result.cameras, ring_scene.rig):
        assert abs(est.center_world_m[2] - gt.center_world_m[2]) < 0.1  # height above the floor
        tilt = lambda c: np.degrees(np.arcsin(-c.R_cam_from_world[2, 2]))  # noqa: E731
        assert abs(tilt(est) - tilt(gt)) < 1.0
        assert np.isclose(np.linalg.det(est.R_cam_from_world), 1.0)
    floor = result.diagnostics.floor
    assert floor.floor_rms_m < 0.05
    assert np.abs(floor.floor_points_m[:, 2]).max() < 1e-9


def test_diagnostics(ring_result):
    intr, result = ring_result
    pv = result.diagnostics.per_view
    assert list(pv["view"]) == [0, 1, 2, 3]
    assert set(pv["focal_status"]) <= {"ok", "poorly_constrained"}
    assert np.all(pv["focal_rel_std"] < 0.05) and np.all(pv["reprojection_rms_px"] < 10)
    assert np.all(pv["rotation_edges"] == 3)
    assert (pv["focal_single_view_px"].to_numpy() == [e.fx_px for e in intr]).all()
    groups = result.diagnostics.groups
    assert groups.groupby("group")["view"].apply(lambda v: v.is_unique).all()
    assert set(result.diagnostics.timings_s) == {"rotations", "linear", "bundle", "regroup", "lens", "views",
                                                  "floor"}
    assert (pv["agreement"] == "ok").all() and not pv["reregistered"].any()


def test_one_view_is_an_error(ring_scene, ring_stand_in):
    d = ring_stand_in.detections
    keep = d.view == 0
    dets = DenseDetections(d.frame[keep], d.view[keep], d.det_id[keep], d.keypoints_px[keep], d.scores[keep])
    lifted = ring_stand_in.lifted.subset(keep)
    intr = estimate_intrinsics(dets, lifted, [(1920, 1080)])
    with pytest.raises(CalibrationError, match="at least two views"):
        estimate_extrinsics(dets, lifted, intr)


def test_view_without_detections_is_an_error(ring_scene, ring_stand_in, ring_result):
    intr, _ = ring_result
    d = ring_stand_in.detections
    keep = d.view != 3
    dets = DenseDetections(d.frame[keep], d.view[keep], d.det_id[keep], d.keypoints_px[keep], d.scores[keep])
    with pytest.raises(CalibrationError, match=r"views \[3\] have no detections"):
        estimate_extrinsics(dets, ring_stand_in.lifted.subset(keep), intr)


def test_two_views(ring_scene, simulate_views):
    cams = [ring_scene.rig[0], ring_scene.rig[2]]
    dets, lifted, _ = simulate_views(ring_scene, cams, seed=5)
    _, result = _calibrate(dets, lifted, cams)
    assert result.diagnostics.regroup == "off: two views"  # the camera-free groups are kept
    err = camera_errors(result.cameras, cams)
    # two cameras facing each other: depth in one view is depth in the other, so the focal lengths rest on the
    # people's metric size, which is free per person (ExtrinsicsConfig.person_scale_std): a few per cent, and
    # the reported uncertainty says so
    std = result.diagnostics.per_view["focal_rel_std"].to_numpy()
    assert np.all(err["focal_error_pct"] < 6.0) and np.all(err["focal_error_pct"] < 300 * std)
    assert np.all(err["angle_error_deg"] < 2.0)


def test_focal_of_a_view_without_upright_people_comes_from_the_others(ring_scene, ring_stand_in):
    lifted = ring_stand_in.lifted
    upright = np.where(ring_stand_in.detections.view == 1, 0.0, lifted.upright_score)
    bent = LiftedPoses(lifted.joints_cam_m, lifted.height_m, upright)
    intr, result = _calibrate(ring_stand_in.detections, bent, list(ring_scene.rig),
                              IntrinsicsConfig(missing_upright="defer"))
    assert intr[1].status == "no_upright"
    assert result.diagnostics.per_view["focal_source"][1] in ("linear+bundle", "resection+bundle")
    err = camera_errors(result.cameras, list(ring_scene.rig))
    assert err["focal_error_pct"][1] < 3.0


def test_straight_down_camera_is_recovered_from_the_other_views(ring_scene, simulate_views, down_camera):
    """Its focal is invisible to its own people and to the linear solve (all people at one depth): resection."""
    cams = list(ring_scene.rig) + [down_camera([0.2, -0.3, 6.5], focal_px=1000.0)]
    dets, lifted, _ = simulate_views(ring_scene, cams, seed=7)
    intr, result = _calibrate(dets, lifted, cams, config=ExtrinsicsConfig(max_groups=100))
    assert intr[-1].status == "ill_conditioned" and intr[-1].tilt_deg > 85
    assert result.diagnostics.per_view["focal_source"].iloc[-1] == "resection+bundle"
    err = camera_errors(result.cameras, cams)
    assert err["focal_error_pct"][-1] < 3.0 and np.all(err["angle_error_deg"] < 1.0)


def test_config_is_validated():
    with pytest.raises(ValueError, match="rotation_threshold_deg"):
        ExtrinsicsConfig(rotation_threshold_deg=0.0)
    with pytest.raises(ValueError, match="focal_range_rel"):
        ExtrinsicsConfig(focal_range_rel=(2.0, 1.0))


def _to_crop(lifted, dets, cameras):
    """The lifter's crop frames: turn each pose by the rotation taking the ray through its box centre onto +z."""
    kp = np.where(dets.scores[..., None] > 0, dets.keypoints_px, np.nan)
    centre = 0.5 * (np.nanmin(kp, axis=1) + np.nanmax(kp, axis=1))
    K = np.stack([c.K for c in cameras])[dets.view]
    ray = np.linalg.solve(K, np.c_[centre, np.ones(len(centre))][..., None])[..., 0]
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    axis = np.cross(ray, [0.0, 0.0, 1.0])
    angle = np.arcsin(np.clip(np.linalg.norm(axis, axis=1), 0, 1))
    from scipy.spatial.transform import Rotation

    rotvec = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12) * angle[:, None]
    R_crop_from_cam = Rotation.from_rotvec(rotvec).as_matrix()
    crop = lifted.joints_cam_m @ R_crop_from_cam.transpose(0, 2, 1)
    return LiftedPoses(crop, lifted.height_m, lifted.upright_score, None, centre, "crop"), K


def test_crop_frame_poses_are_turned_into_camera_frames(ring_scene, ring_stand_in):
    cams = list(ring_scene.rig)
    crop, K = _to_crop(ring_stand_in.lifted, ring_stand_in.detections, cams)
    assert crop.frame == "crop"
    back = crop.in_camera_frame(K)
    assert np.allclose(back.joints_cam_m, ring_stand_in.lifted.joints_cam_m, atol=1e-9)
    _, result = _calibrate(ring_stand_in.detections, crop, cams, config=ExtrinsicsConfig(max_groups=100))
    err = camera_errors(result.cameras, cams)
    assert np.all(err["focal_error_pct"] < 3.0) and np.all(err["angle_error_deg"] < 1.0)
