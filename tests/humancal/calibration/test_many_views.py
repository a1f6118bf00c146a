"""Short captures use all their frames; views that share no people with the others are named; many views."""

import time

import numpy as np
import pytest

from evaluation.camera_metrics import camera_errors
from humancal.calibration import CalibrationError, IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
from humancal.tables.detections import DenseDetections

DEFER = IntrinsicsConfig(missing_upright="defer")


def _sizes(cameras):
    return [(c.width_px, c.height_px) for c in cameras]


@pytest.fixture(scope="module")
def short_scene(body_model):
    """3 people, 4 views on a ring, 20 frames (a short capture)."""
    from evaluation.oracle import stand_in_lifted_poses
    from humancal.synthetic import generate_scene, preset

    scene = generate_scene(preset("demo", num_people=3, num_views=4, num_frames=20, seed=7), body_model,
                           sequence="short")
    return scene, stand_in_lifted_poses(scene, np.random.default_rng(0))


def test_short_capture_uses_every_frame(short_scene):
    scene, stand_in = short_scene
    d, lifted = stand_in.detections, stand_in.lifted
    result = estimate_extrinsics(d, lifted, estimate_intrinsics(d, lifted, _sizes(scene.rig), DEFER))
    groups = result.diagnostics.groups
    assert groups["frame"].nunique() == 20  # no frame thrown away by a sub-sampling cap
    # (nearly) every person of every frame seen by two views is a group of the bundle adjustment
    seen = stand_in.person_id >= 0
    frame_person = {(f, p) for f, p in zip(d.frame[seen], stand_in.person_id[seen])}
    assert groups["group"].nunique() >= 0.9 * len(frame_person)
    err = camera_errors(result.cameras, list(scene.rig))
    assert np.all(err["focal_error_pct"] < 5.0) and np.all(err["angle_error_deg"] < 2.0), err


def _moved(stand_in, views, offset=10_000):
    """The detections with the frames of ``views`` moved away: those views share no frame with the others."""
    d = stand_in.detections
    frame = np.where(np.isin(d.view, views), d.frame + offset, d.frame)
    return DenseDetections(frame, d.view, d.det_id, d.keypoints_px, d.scores)


def test_a_view_that_matches_nobody_is_named(ring_scene, ring_stand_in):
    d = _moved(ring_stand_in, [2])
    intr = estimate_intrinsics(d, ring_stand_in.lifted, _sizes(ring_scene.rig), DEFER)
    names = ["north", "east", "south", "west"]
    with pytest.raises(CalibrationError, match=r"'south' \(view 2\) match no person seen by the other views") as e:
        estimate_extrinsics(d, ring_stand_in.lifted, intr, view_names=names)
    assert "'north' (view 0), 'east' (view 1), 'west' (view 3)" in str(e.value)
    with pytest.raises(CalibrationError, match=r"view 2 match no person"):
        estimate_extrinsics(d, ring_stand_in.lifted, intr)


def test_a_separate_group_of_views_is_named(ring_scene, ring_stand_in):
    """Views 0 and 1 see the people at other times than views 2 and 3: two parts, the second is named."""
    d = _moved(ring_stand_in, [2, 3])
    intr = estimate_intrinsics(d, ring_stand_in.lifted, _sizes(ring_scene.rig), DEFER)
    with pytest.raises(CalibrationError, match=r"view 2, view 3 share people only among themselves"):
        estimate_extrinsics(d, ring_stand_in.lifted, intr)


def test_view_names_must_match_the_views(ring_scene, ring_stand_in):
    d = ring_stand_in.detections
    intr = estimate_intrinsics(d, ring_stand_in.lifted, _sizes(ring_scene.rig), DEFER)
    with pytest.raises(ValueError, match="view_names"):
        estimate_extrinsics(d, ring_stand_in.lifted, intr, view_names=["a", "b"])


@pytest.mark.slow
def test_31_views_short_capture_with_the_shipped_lifter(body_model):
    """31 cameras on a ring, 3 people, 20 frames, the shipped lifter: solved, with its time (printed)."""
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset
    from humancal.tables.detections import detections_to_dense

    scene = generate_scene(preset("demo", num_people=3, num_views=31, num_frames=20, seed=6), body_model,
                           sequence="ring31")
    d = detections_to_dense(scene.detections)
    lifted = lift_detections(load_lifter(shipped_checkpoint()), d.keypoints_px, d.scores)
    start = time.perf_counter()
    intr = estimate_intrinsics(d, lifted, _sizes(scene.rig), DEFER)
    result = estimate_extrinsics(d, lifted, intr)
    seconds = time.perf_counter() - start
    err = camera_errors(result.cameras, list(scene.rig))
    print(f"31 views, 20 frames: {seconds:.1f} s (extrinsics stages {result.diagnostics.timings_s}); focal error "
          f"median {np.median(err['focal_error_pct']):.2f} %, angle median {np.median(err['angle_error_deg']):.2f} "
          f"deg, position median {np.median(err['position_error_mm']):.0f} mm")
    assert result.diagnostics.groups["frame"].nunique() == 20
    assert np.median(err["focal_error_pct"]) < 3.0 and np.max(err["angle_error_deg"]) < 2.0
    assert np.median(err["position_error_mm"]) < 100.0
