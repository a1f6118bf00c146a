"""Known cameras: all views known, they come back as given and are checked against the people; some views known,
the others are calibrated around them and the world is theirs; the final cameras of a run."""

import numpy as np
import pytest

from evaluation.camera_metrics import camera_errors
from humancal.calibration import ExtrinsicsConfig, IntrinsicsConfig, estimate_extrinsics, estimate_intrinsics
from humancal.calibration.final import choose_final_cameras
from humancal.camera import Camera, CameraRig
from humancal.geometry.rotations import rotvec_to_rotmat


@pytest.fixture(scope="module")
def ring(ring_scene, ring_stand_in):
    detections, lifted = ring_stand_in.detections, ring_stand_in.lifted
    rig = list(ring_scene.rig)
    intrinsics = estimate_intrinsics(detections, lifted, [(c.width_px, c.height_px) for c in rig],
                                     IntrinsicsConfig(missing_upright="defer"))
    return rig, detections, lifted, intrinsics


def test_every_view_known_comes_back_as_given_and_agrees(ring):
    rig, detections, lifted, intrinsics = ring
    result = estimate_extrinsics(detections, lifted, intrinsics, known=dict(enumerate(rig)))
    given = CameraRig.from_cameras(rig)
    for name in ("K", "R_cam_from_world", "t_cam_from_world_m", "distortion", "image_size_px"):
        np.testing.assert_array_equal(getattr(result.cameras, name), getattr(given, name))
    assert result.diagnostics.world_frame == "known_cameras"
    per_view = result.diagnostics.per_view
    assert (per_view["agreement"] == "ok").all() and (per_view["focal_source"] == "known").all()
    assert 0.8 < result.diagnostics.body_size_ratio < 1.25


def test_a_known_camera_file_in_another_view_order_disagrees(ring):
    rig, detections, lifted, intrinsics = ring
    swapped = {0: rig[1], 1: rig[0], 2: rig[2], 3: rig[3]}
    per_view = estimate_extrinsics(detections, lifted, intrinsics, known=swapped).diagnostics.per_view
    assert set(per_view.loc[per_view["agreement"] == "disagrees", "view"]) >= {0, 1}


@pytest.mark.parametrize("known_views", [[2], [0, 3]])
def test_known_views_are_held_and_set_the_world(ring, known_views):
    rig, detections, lifted, intrinsics = ring
    result = estimate_extrinsics(detections, lifted, intrinsics, known={v: rig[v] for v in known_views})
    assert result.diagnostics.world_frame == "known_cameras"
    for v in known_views:  # held exactly
        np.testing.assert_allclose(result.cameras[v].K, rig[v].K)
        np.testing.assert_allclose(result.cameras[v].R_cam_from_world, rig[v].R_cam_from_world, atol=1e-12)
        np.testing.assert_allclose(result.cameras[v].t_cam_from_world_m, rig[v].t_cam_from_world_m, atol=1e-12)
    errors = camera_errors(result.cameras, rig)
    assert errors["focal_error_pct"].max() < 3.0 and errors["angle_error_deg"].max() < 1.0
    # no alignment needed: the world is the known cameras'; two known cameras also fix the scale, one leaves it to
    # the people's limbs (these three people are about 8 % smaller than the reference adult)
    off = np.array([np.linalg.norm(c.center_world_m - g.center_world_m) for c, g in zip(result.cameras, rig)])
    if len(known_views) == 2:
        assert off.max() < 0.15
    else:
        anchor = rig[known_views[0]].center_world_m
        distance = np.array([np.linalg.norm(g.center_world_m - anchor) for g in rig])
        assert np.all(off <= 0.12 * distance)


def test_the_refined_cameras_are_final_unless_the_refinement_broke_a_view(ring, ring_stand_in):
    rig, detections, _, _ = ring
    person = ring_stand_in.person_id
    good = choose_final_cameras(CameraRig.from_cameras(rig), CameraRig.from_cameras(rig), detections, person)
    assert good.source == "refined_cameras" and (good.agreement["verdict"] == "ok").all()
    broken = list(rig)
    c = broken[1]
    broken[1] = Camera.from_center(c.K, rotvec_to_rotmat(np.radians([0.0, 8.0, 0.0])) @ c.R_cam_from_world,
                                   c.center_world_m, c.width_px, c.height_px)
    choice = choose_final_cameras(CameraRig.from_cameras(rig), CameraRig.from_cameras(broken), detections, person)
    assert choice.source == "extrinsics" and "views [1]" in choice.reason
    assert choose_final_cameras(CameraRig.from_cameras(rig), None, detections, person).source == "extrinsics"


def test_known_cameras_set_off_the_floor_alignment_and_the_limb_scale(ring):
    rig, detections, lifted, intrinsics = ring
    config = ExtrinsicsConfig(scale_from_limbs=True)
    result = estimate_extrinsics(detections, lifted, intrinsics, config, known={0: rig[0], 1: rig[1]})
    assert result.diagnostics.floor is None
