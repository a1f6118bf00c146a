"""The lens step of the calibration: a distorting lens's k1 recovered from the people, pinholes kept as pinholes,
and the held-out comparison's folds."""

import numpy as np
import pytest

from humancal.calibration import ExtrinsicsConfig, IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
from humancal.calibration.lens import frame_folds
from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
from humancal.synthetic import generate_scene, preset
from humancal.tables.detections import detections_to_dense


def _calibrate(scene, config=None):
    d = detections_to_dense(scene.detections)
    lifted = lift_detections(load_lifter(shipped_checkpoint()), d.keypoints_px, d.scores)
    intr = estimate_intrinsics(d, lifted, [(c.width_px, c.height_px) for c in scene.rig],
                               IntrinsicsConfig(missing_upright="defer"))
    return estimate_extrinsics(d, lifted, intr, config)


@pytest.fixture(scope="module")
def barrel_scene(body_model):
    """4 people, 5 views, 60 frames, every lens k1 in [-0.12, -0.08]."""
    return generate_scene(preset("demo", num_frames=60, distortion_k1_range=(-0.12, -0.08), seed=5), body_model,
                          sequence="barrel")


def test_a_barrel_lens_is_recovered_and_the_rig_with_it(barrel_scene):
    from evaluation.camera_metrics import camera_errors

    truth = np.array([c.distortion[0] for c in barrel_scene.rig])
    pinhole = _calibrate(barrel_scene, ExtrinsicsConfig(lens_models=("pinhole",)))
    lens = _calibrate(barrel_scene)
    k1, k1_std = lens.diagnostics.per_view["k1"].to_numpy(), lens.diagnostics.per_view["k1_std"].to_numpy()
    assert np.median(np.abs(k1 - truth)) < 0.03 and (np.abs(k1 - truth) < 2 * k1_std).all(), (k1, k1_std, truth)
    np.testing.assert_allclose([c.distortion[0] for c in lens.cameras], k1)  # the cameras carry it out
    assert lens.diagnostics.lens.model == "k1" and not lens.diagnostics.lens.pinhole_views
    before, after = camera_errors(pinhole.cameras, list(barrel_scene.rig)), camera_errors(lens.cameras,
                                                                                           list(barrel_scene.rig))
    assert np.median(after["focal_error_pct"]) < 0.5 < np.median(before["focal_error_pct"])
    assert np.median(after["position_error_mm"]) < 0.3 * np.median(before["position_error_mm"])
    assert (lens.diagnostics.per_view["agreement"] == "ok").all()


@pytest.fixture(scope="module")
def pinhole_scene(body_model):
    """4 people, 5 pinhole views at the image centre, 60 frames."""
    return generate_scene(preset("demo", num_frames=60), body_model, sequence="pinhole")


def test_pinhole_views_stay_pinholes(pinhole_scene):
    result = _calibrate(pinhole_scene)
    per_view = result.diagnostics.per_view
    assert (per_view["k1"] == 0.0).all()
    assert all(not np.any(c.distortion) for c in result.cameras)
    assert "kept as pinholes" in result.diagnostics.lens.reason
    assert per_view[["cx_std_px", "cy_std_px"]].isna().all().all()  # the principal point was not estimated


def test_a_view_kept_a_pinhole_still_estimates_its_principal_point(pinhole_scene):
    """With the principal point estimated, the views whose k1 is 0 hold their radial terms only: each principal point
    moves and has its std in the per-view table."""
    result = _calibrate(pinhole_scene, ExtrinsicsConfig(principal_point="estimate"))
    per_view = result.diagnostics.per_view
    assert result.diagnostics.lens.principal_point == "estimated"
    assert (per_view["k1"] == 0.0).all(), per_view["k1"]
    centre = np.array([[c.width_px / 2.0, c.height_px / 2.0] for c in pinhole_scene.rig])
    moved = np.hypot(per_view["cx_px"] - centre[:, 0], per_view["cy_px"] - centre[:, 1])
    assert (moved > 0.01).all(), moved
    std = per_view[["cx_std_px", "cy_std_px"]].to_numpy()
    assert np.isfinite(std).all() and (std > 0).all() and (std < 50.0).all(), std  # below the 50 px prior's


def test_frame_folds_alternate_blocks_of_consecutive_frames():
    frames = np.repeat(np.arange(60), 2)
    folds = frame_folds(frames, blocks=6)
    assert np.bincount(folds).tolist() == [60, 60]
    assert (folds[frames < 10] == 0).all() and (folds[(frames >= 10) & (frames < 20)] == 1).all()


def test_two_people_are_enough_to_keep_an_action_cameras_k1(body_model):
    """Two people over 40 frames leave each k1 of a 110-degree lens uncertain to about 0.05-0.1, yet 3-5 stds from
    0: the lens is kept (a pinhole there is several % off in focal)."""
    from evaluation.camera_metrics import camera_errors

    scene = generate_scene(preset("action_cam", num_people=2, num_views=6, num_frames=40, behaviour="mixed",
                                  seed=16), body_model, sequence="action")
    truth = np.array([c.distortion[0] for c in scene.rig])
    result = _calibrate(scene)
    k1, k1_std = result.diagnostics.per_view["k1"].to_numpy(), result.diagnostics.per_view["k1_std"].to_numpy()
    assert (k1 != 0.0).sum() >= 5, (k1, k1_std)
    assert np.median(np.abs(k1 - truth)[k1 != 0.0]) < 0.08, (k1, truth)
    strict = _calibrate(scene, ExtrinsicsConfig(lens_max_k1_std=0.05))
    focal = np.median(camera_errors(result.cameras, list(scene.rig))["focal_error_pct"])
    focal_strict = np.median(camera_errors(strict.cameras, list(scene.rig))["focal_error_pct"])
    assert focal < focal_strict, (focal, focal_strict, strict.diagnostics.lens.reason)
