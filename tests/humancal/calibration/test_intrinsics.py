"""Single-view intrinsics on a synthetic scene with stand-in lifted poses: diagnostics and failure modes."""

import numpy as np
import pytest

from humancal.calibration import CalibrationError, IntrinsicsConfig, LiftedPoses, estimate_intrinsics
from humancal.tables.detections import DenseDetections


def _sizes(scene):
    return [(c.width_px, c.height_px) for c in scene.rig]


def _subset(dets: DenseDetections, keep: np.ndarray) -> DenseDetections:
    return DenseDetections(dets.frame[keep], dets.view[keep], dets.det_id[keep], dets.keypoints_px[keep],
                           dets.scores[keep])


def test_diagnostics_describe_each_view(ring_scene, ring_stand_in):
    est = estimate_intrinsics(ring_stand_in.detections, ring_stand_in.lifted, _sizes(ring_scene))
    assert [e.view for e in est] == list(range(len(ring_scene.rig)))
    for e, cam in zip(est, ring_scene.rig):
        up_true = cam.R_cam_from_world @ [0, 0, 1.0]
        tilt_true = np.degrees(np.arcsin(-up_true[2]))
        assert e.status in ("ok", "ill_conditioned")
        assert e.num_inliers >= 6 and e.num_inliers <= e.num_candidates
        assert np.isfinite(e.fx_px) and e.fx_px == e.fy_px  # square pixels by default
        assert np.allclose(e.K[:2, 2], [cam.width_px / 2, cam.height_px / 2])
        # the up direction (roll and tilt) is what a single view sees well
        assert np.degrees(np.arccos(np.clip(e.up_cam @ up_true, -1, 1))) < 8.0
        assert abs(e.tilt_deg - tilt_true) < 8.0
        assert abs(e.camera_height_m / cam.center_world_m[2] - 1) < 0.35
        assert e.focal_rel_uncertainty > 0
        if e.status == "ok":  # a focal claimed good must be within a few uncertainties
            assert abs(e.fx_px / cam.K[0, 0] - 1) < 4 * e.focal_rel_uncertainty + 0.02


def test_no_upright_person_raises_naming_the_view(ring_scene, ring_stand_in):
    lifted = ring_stand_in.lifted
    upright = np.where(ring_stand_in.detections.view == 2, 0.0, lifted.upright_score)
    bent = LiftedPoses(lifted.joints_cam_m, lifted.height_m, upright)
    with pytest.raises(CalibrationError, match="view 2: only 0 upright detections"):
        estimate_intrinsics(ring_stand_in.detections, bent, _sizes(ring_scene))
    deferred = estimate_intrinsics(ring_stand_in.detections, bent, _sizes(ring_scene),
                                   IntrinsicsConfig(missing_upright="defer"))
    assert deferred[2].status == "no_upright" and np.isnan(deferred[2].fx_px)
    assert deferred[2].focal_rel_uncertainty == np.inf
    assert all(e.status != "no_upright" for v, e in enumerate(deferred) if v != 2)


def test_view_without_detections_raises(ring_scene, ring_stand_in):
    keep = ring_stand_in.detections.view != 1
    dets = _subset(ring_stand_in.detections, keep)
    with pytest.raises(CalibrationError, match="view 1 has no detections"):
        estimate_intrinsics(dets, ring_stand_in.lifted.subset(keep), _sizes(ring_scene))


def test_straight_down_camera_is_flagged(ring_scene, simulate_views, down_camera):
    """Looking straight down, the vanishing point is the image centre and heights give the camera height only."""
    cam = down_camera([0.3, -0.2, 6.5], focal_px=1000.0)
    dets, lifted, _ = simulate_views(ring_scene, [cam])
    (est,) = estimate_intrinsics(dets, lifted, [(cam.width_px, cam.height_px)])
    assert est.status == "ill_conditioned"
    assert est.tilt_deg > 85.0
    assert np.linalg.norm(est.vanishing_point_px - cam.K[:2, 2]) < 60.0
    assert abs(est.camera_height_m / 6.5 - 1) < 0.15


def test_inputs_are_checked(ring_scene, ring_stand_in):
    dets, lifted = ring_stand_in.detections, ring_stand_in.lifted
    with pytest.raises(ValueError, match="one per row"):
        estimate_intrinsics(dets, lifted.subset(np.arange(5)), _sizes(ring_scene))
    with pytest.raises(ValueError, match="views"):
        estimate_intrinsics(dets, lifted, _sizes(ring_scene)[:2])
    with pytest.raises(ValueError, match="principal_point_px"):
        estimate_intrinsics(dets, lifted, _sizes(ring_scene), principal_point_px=[(0, 0)])
    with pytest.raises(ValueError, match="plumb line"):
        IntrinsicsConfig(plumb_top="knees")
    with pytest.raises(ValueError, match="upright_score"):
        LiftedPoses(lifted.joints_cam_m[:2], lifted.height_m[:2], np.array([0.5, 1.5]))


def test_invalid_lifts_are_ignored(ring_scene, ring_stand_in):
    from humancal.calibration.rotation_consensus import pairwise_rotations

    lifted = ring_stand_in.lifted
    valid = np.random.default_rng(0).random(len(lifted)) > 0.2
    joints = np.where(valid[:, None, None], lifted.joints_cam_m, np.nan)
    adopted = LiftedPoses(joints, np.where(valid, lifted.height_m, np.nan),
                          np.where(valid, lifted.upright_score, np.nan), valid, np.zeros((len(lifted), 2)))
    assert adopted.frame == "camera" and np.isnan(adopted.upright_score[~valid]).all()
    est = estimate_intrinsics(ring_stand_in.detections, adopted, _sizes(ring_scene))
    assert all(np.isfinite(e.fx_px) for e in est)
    pairs = pairwise_rotations(ring_stand_in.detections, adopted, 4, np.random.default_rng(0))
    assert all(valid[p.rows_a].all() and valid[p.rows_b].all() for p in pairs)
    with pytest.raises(ValueError, match="finite in every valid row"):
        LiftedPoses(joints, lifted.height_m, lifted.upright_score)
