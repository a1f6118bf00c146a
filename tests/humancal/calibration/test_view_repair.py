"""A capture where the calibration's first rig is wrong (seated people, 20 frames, 5 views): the views that disagree
with the others are found, placed again and the rig ends right; with the repair off, the same views are named."""

import pytest

from evaluation.camera_metrics import camera_errors
from humancal.calibration import ExtrinsicsConfig, IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
from humancal.tables.plausibility import check_views_agree


@pytest.fixture(scope="module")
def seated(body_model):
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset
    from humancal.tables.detections import detections_to_dense

    scene = generate_scene(preset("demo", seed=1014, behaviour="seated", num_frames=20, num_views=5, num_people=3),
                           body_model, sequence="seated")
    dense = detections_to_dense(scene.detections)
    lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores)
    intrinsics = estimate_intrinsics(dense, lifted, [(c.width_px, c.height_px) for c in scene.rig],
                                     IntrinsicsConfig(missing_upright="defer"))
    return list(scene.rig), dense, lifted, intrinsics


def test_views_that_disagree_are_placed_again(seated):
    rig, dense, lifted, intrinsics = seated
    result = estimate_extrinsics(dense, lifted, intrinsics)
    per_view = result.diagnostics.per_view
    assert (per_view["first_agreement"] == "disagrees").sum() >= 2 and per_view["reregistered"].sum() >= 1
    assert (per_view["agreement"] == "ok").all() and check_views_agree(per_view).passed
    errors = camera_errors(result.cameras, rig)
    assert errors["focal_error_pct"].max() < 3.0 and errors["angle_error_deg"].max() < 0.5


def test_without_the_repair_the_wrong_views_are_named_and_the_run_would_stop(seated):
    rig, dense, lifted, intrinsics = seated
    result = estimate_extrinsics(dense, lifted, intrinsics, ExtrinsicsConfig(repair_views=False))
    per_view = result.diagnostics.per_view
    assert not per_view["reregistered"].any() and (per_view["agreement"] == "disagrees").any()
    report = check_views_agree(per_view, [f"cam{v}" for v in range(5)])
    assert not report.passed and "disagrees with the other views" in report.description
    assert "(cam" in report.description and "--drop-view" in report.description
    errors = camera_errors(result.cameras, rig)
    assert errors["focal_error_pct"].max() > 10.0  # the rig the check stopped was wrong indeed
