"""generate_scene: tables, determinism, exact projections with a perfect detector."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from humancal.camera import Camera, cameras_from_table, project_points
from humancal.keypoints import CANONICAL_JOINTS, FLIP_INDEX, JOINT_INDEX, NUM_JOINTS
from humancal.synthetic import DetectorNoise, SceneConfig, generate_scene, preset, simulate_detections
from humancal.tables.schemas import SCHEMAS

TABLES = ("detections", "cameras", "poses3d", "associations", "people", "motions")


def _with_truth(scene, mirror: bool = False) -> pd.DataFrame:
    """Detections joined with their true person and the projection of that person's joint (of the joint's
    left/right twin when ``mirror``)."""
    rows = scene.detections.merge(scene.associations, on=["sequence", "frame", "view", "det_id"], validate="m:1")
    rows = rows[rows.person_id >= 0]
    joint = rows.joint.map(JOINT_INDEX).to_numpy()
    if mirror:
        joint = np.asarray(FLIP_INDEX)[joint]
    truth = np.empty((len(rows), 2))
    for v, camera in enumerate(scene.rig):
        mask = rows.view.to_numpy() == v
        points = scene.keypoints_world_m[rows.person_id.to_numpy()[mask], rows.frame.to_numpy()[mask], joint[mask]]
        truth[mask] = project_points(camera, points)[0]
    return rows.assign(true_x=truth[:, 0], true_y=truth[:, 1])


def test_tables_have_the_canonical_schemas(tiny_scene):
    for name in TABLES:
        table = getattr(tiny_scene, name)
        assert list(table.columns) == SCHEMAS[name].names, name
        assert (table.sequence == "tiny").all()
    P, F, V = 2, 20, 3
    assert len(tiny_scene.poses3d) == P * F * NUM_JOINTS and tiny_scene.poses3d.valid.all()
    assert len(tiny_scene.people) == P and len(tiny_scene.cameras) == V and len(tiny_scene.motions) == P * F
    assert set(tiny_scene.detections.joint) <= set(CANONICAL_JOINTS)
    assert tiny_scene.detections.score.between(0.0, 1.0).all()
    # One association per detection, and every detection row has its association.
    keys = ["frame", "view", "det_id"]
    assert not tiny_scene.associations.duplicated(keys).any()
    assert len(tiny_scene.detections[keys].drop_duplicates()) == len(tiny_scene.associations)
    np.testing.assert_allclose(tiny_scene.people.height_m, tiny_scene.height_m)
    assert tiny_scene.people.height_m.between(1.5, 1.95).all()
    cams = cameras_from_table(tiny_scene.cameras)
    assert all(np.allclose(a.P, b.P) for a, b in zip(cams, tiny_scene.rig))


def test_det_ids_are_a_shuffled_permutation_per_frame_and_view(tiny_scene):
    assoc = tiny_scene.associations
    for _, group in assoc.groupby(["frame", "view"]):
        assert sorted(group.det_id) == list(range(len(group)))
    # The order of det_ids leaks no identity: person 0 is not always det 0.
    two = assoc.groupby(["frame", "view"]).filter(lambda g: (g.person_id >= 0).sum() == 2)
    first = two[two.det_id == 0].person_id
    assert 0 < (first == 0).mean() < 1


def test_same_seed_same_scene_and_other_seed_differs(body_model, tiny_scene):
    again = generate_scene(preset("tiny"), body_model, sequence="tiny")
    for name in TABLES:
        pd.testing.assert_frame_equal(getattr(again, name), getattr(tiny_scene, name), check_exact=True)
    other = generate_scene(preset("tiny", seed=1), body_model, sequence="tiny")
    for name in ("detections", "cameras", "poses3d", "people"):
        assert not getattr(other, name).equals(getattr(tiny_scene, name)), name


def test_noise_settings_do_not_change_people_motion_or_cameras(body_model, tiny_scene):
    clean = generate_scene(preset("tiny", noise=DetectorNoise.none()), body_model, sequence="tiny")
    pd.testing.assert_frame_equal(clean.poses3d, tiny_scene.poses3d)
    pd.testing.assert_frame_equal(clean.cameras, tiny_scene.cameras)
    assert not clean.detections.equals(tiny_scene.detections)


def test_perfect_detector_reports_exact_projections(clean_scene):
    rows = _with_truth(clean_scene)
    assert len(rows) == len(clean_scene.detections)  # no false positives
    np.testing.assert_allclose(rows.x_px, rows.true_x, atol=1e-6)
    np.testing.assert_allclose(rows.y_px, rows.true_y, atol=1e-6)
    assert (rows.score == 1.0).all()
    # Every joint in the image is reported, none outside it; every person with a visible joint is detected.
    d = clean_scene.detector
    assert d.present.sum() == d.in_image[d.view, d.person_id, d.frame].sum()
    assert (d.detected == d.eligible).all()
    assert d.eligible.sum() >= 0.9 * d.eligible.size
    for camera, view in zip(clean_scene.rig, range(len(clean_scene.rig))):
        inside = rows[rows.view == view]
        assert inside.x_px.between(0, camera.width_px).all() and inside.y_px.between(0, camera.height_px).all()


def test_left_right_flips_swap_the_labels(body_model):
    config = preset("tiny_clean", noise=dataclasses.replace(DetectorNoise.none(), flip_rate=1.0))
    scene = generate_scene(config, body_model, sequence="flipped")
    assert scene.detector.flipped.all()
    swapped = _with_truth(scene, mirror=True)
    np.testing.assert_allclose(swapped.x_px, swapped.true_x, atol=1e-6)
    np.testing.assert_allclose(swapped.y_px, swapped.true_y, atol=1e-6)
    labelled = _with_truth(scene)
    sided = labelled.joint.str.startswith(("left_", "right_")).to_numpy()
    assert np.abs(labelled.x_px - labelled.true_x).to_numpy()[sided].mean() > 5.0


def test_people_outside_every_image_give_no_detection(body_model):
    config = SceneConfig(num_people=1, num_views=2, num_frames=5, seed=3, noise=DetectorNoise.none())
    scene = generate_scene(config, body_model, sequence="away")
    assert len(scene.detections) > 0
    # Turn every camera around: the person is behind all of them.
    turn = np.diag([-1.0, 1.0, -1.0])  # half a turn about the image y axis: same centre, opposite view
    away = [
        Camera(c.K, turn @ c.R_cam_from_world, turn @ c.t_cam_from_world_m, c.width_px, c.height_px) for c in scene.rig
    ]
    assert all(np.allclose(a.center_world_m, c.center_world_m) for a, c in zip(away, scene.rig))
    out = simulate_detections(scene.keypoints_world_m, scene.height_m, away, config.noise, np.random.default_rng(0))
    assert out.num_detections == 0 and not out.in_image.any()


def test_progress_reports_reach_one(body_model):
    stages = []
    generate_scene(preset("tiny", num_frames=5), body_model, sequence="p", progress=lambda s, f: stages.append((s, f)))
    fractions = [f for _, f in stages]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert [s for s, _ in stages][-1] == "tables"


def test_generate_scene_rejects_bad_arguments(body_model):
    with pytest.raises(ValueError, match="SceneConfig"):
        generate_scene({"num_people": 2}, body_model)
    with pytest.raises(ValueError, match="sequence"):
        generate_scene(preset("tiny"), body_model, sequence="")


@pytest.mark.benchmark
def test_demo_generation_time(body_model):
    import time

    start = time.perf_counter()
    scene = generate_scene(preset("demo"), body_model, sequence="demo")
    elapsed = time.perf_counter() - start
    print(f"demo scene (4 people x 5 views x 300 frames): {elapsed:.2f} s, {scene.summary()}")
    assert scene.keypoints_world_m.shape == (4, 300, NUM_JOINTS, 3)


def test_a_biased_detector_sees_every_keypoint_moved_in_its_bone(body_model):
    from humancal.synthetic.noise import draw_keypoint_bias

    offsets = draw_keypoint_bias(0.01, np.random.default_rng(0))
    for k, twin in enumerate(FLIP_INDEX):  # mirrored: a right keypoint's offset is its left twin's, X negated
        np.testing.assert_allclose(offsets[twin], offsets[k] * [-1.0, 1.0, 1.0])
    assert np.abs(offsets).max() > 0.005

    config = preset("tiny_clean", num_people=2, num_views=3, num_frames=20, seed=5)
    plain = generate_scene(config, body_model, sequence="bias")
    biased = generate_scene(config.replace(noise=dataclasses.replace(config.noise, keypoint_bias_m=0.02)),
                            body_model, sequence="bias")
    # the truth and the cameras are the unbiased scene's; only what the detector reports moved
    pd.testing.assert_frame_equal(biased.poses3d, plain.poses3d)
    pd.testing.assert_frame_equal(biased.cameras, plain.cameras)
    keys = ["frame", "view", "det_id", "joint"]
    both = plain.detections.merge(biased.detections, on=keys, suffixes=("", "_biased"))
    assert len(both) > 0.9 * len(plain.detections)
    moved_px = np.hypot(both.x_px - both.x_px_biased, both.y_px - both.y_px_biased)
    assert np.median(moved_px) > 1.0 and moved_px.max() < 60.0
    # reproducible (with no bias the golden scenes of test_golden_scenes stay bit for bit as they were)
    again = generate_scene(config.replace(noise=dataclasses.replace(config.noise, keypoint_bias_m=0.02)),
                           body_model, sequence="bias")
    pd.testing.assert_frame_equal(again.detections, biased.detections)
