"""Bundle adjustment, floor alignment, similarity alignment, the stand-in lifter and the rig plot."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evaluation.oracle import lift_ground_truth, upright_scores
from humancal.calibration import align_rig, align_to_floor, plot_rigs
from humancal.calibration.floor import NoFloorError
from humancal.synthetic.activities import ACTIVITIES
from humancal.calibration.bundle import bundle_adjust
from humancal.geometry.alignment import fit_similarity
from humancal.geometry.rotations import rotvec_to_rotmat
from humancal.lifter import standing_score
from humancal.camera import Camera, project_points


def test_bundle_adjustment_recovers_perturbed_cameras(ring_scene, ring_stand_in, ring_true_groups):
    d, lifted, pid = ring_stand_in.detections, ring_stand_in.lifted, ring_stand_in.person_id
    rig = list(ring_scene.rig)
    V = len(rig)
    groups, points = ring_true_groups
    rng = np.random.default_rng(0)
    R_true = np.stack([c.R_cam_from_world for c in rig])
    t_true = np.stack([c.t_cam_from_world_m for c in rig])
    f_true = np.array([c.K[0, 0] for c in rig])
    R0 = rotvec_to_rotmat(np.radians(2.0) * rng.normal(size=(V, 3))) @ R_true
    R0[0] = R_true[0]
    t0 = t_true + 0.2 * rng.normal(size=(V, 3))
    t0[0] = t_true[0]
    f0 = f_true * np.array([1.0, 1.15, 0.85, 1.1])
    pp = np.stack([c.K[:2, 2] for c in rig])
    res = bundle_adjust(d, lifted, groups, points + 0.05 * rng.normal(size=points.shape), f0, f0, pp, R0, t0)
    assert np.all(np.abs(res.fx_px / f_true - 1) < 0.02), res.fx_px / f_true
    centres = -np.einsum("vji,vj->vi", res.R_cam_from_world, res.t_cam_from_world_m)
    true_centres = np.stack([c.center_world_m for c in rig])
    assert np.linalg.norm(centres - true_centres, axis=1).max() < 0.1  # scale from the noisy lifted shapes
    assert np.all(res.reprojection_rms_px < 8) and res.inlier_fraction > 0.9
    # the stated uncertainty: below the poorly-constrained label (5 %), and the errors within three of it
    assert np.all(res.focal_rel_std < 0.05), res.focal_rel_std
    assert np.all(np.abs(res.fx_px / f_true - 1) < 3 * res.focal_rel_std), (res.fx_px / f_true, res.focal_rel_std)


def test_bundle_adjustment_with_wrong_people_sizes(ring_scene, ring_stand_in, ring_true_groups):
    """Lifted poses of each person scaled by that person's size error: the group scales absorb it."""
    d, pid = ring_stand_in.detections, ring_stand_in.person_id
    rig = list(ring_scene.rig)
    V = len(rig)
    size = np.array([0.88, 1.12, 0.93])
    lifted = lift_ground_truth(ring_scene.keypoints_world_m, ring_scene.height_m, rig, d.frame, d.view, pid,
                               np.zeros(len(d), bool), np.random.default_rng(0), joint_noise_m=0.03,
                               height_noise_m=0.0, rotation_noise_deg=0.0, depth_flip_rate=0.0)
    scaled = lifted.joints_cam_m * size[np.maximum(pid, 0)][:, None, None]
    lifted = type(lifted)(scaled, lifted.height_m, lifted.upright_score, lifted.valid)
    groups, points = ring_true_groups
    R = np.stack([c.R_cam_from_world for c in rig])
    t = np.stack([c.t_cam_from_world_m for c in rig])
    f_true = np.array([c.K[0, 0] for c in rig])
    f0 = f_true * np.array([1.0, 1.1, 0.9, 1.05])
    pp = np.stack([c.K[:2, 2] for c in rig])
    naive = bundle_adjust(d, lifted, groups, points, f0, f0, pp, R, t, shape_std_m=0.05)
    assert np.max(np.abs(naive.fx_px / f_true - 1)) > 0.05  # the sizes pull the cameras without group scales
    res = bundle_adjust(d, lifted, groups, points, f0, f0, pp, R, t, shape_std_m=0.05, group_scale_std=0.1)
    assert np.all(np.abs(res.fx_px / f_true - 1) < 0.02), res.fx_px / f_true
    assert np.all(np.abs(res.fx_px / f_true - 1) < 2.5 * res.focal_rel_std)  # as uncertain as it says
    q = res.group_scale / size[np.array([pid[g[0]] for g in groups])]
    assert np.std(np.log(q)) < 0.02  # each group's scale follows its person's size error
    # the metric scale of the scene is the (geometric) mean of the lifted sizes: c = 1 / mean q
    centres = -np.einsum("vji,vj->vi", res.R_cam_from_world, res.t_cam_from_world_m)
    true_centres = np.stack([c.center_world_m for c in rig])
    baseline = np.linalg.norm(centres[1:] - centres[0], axis=1)
    ratio = baseline / np.linalg.norm(true_centres[1:] - true_centres[0], axis=1)
    assert np.all(np.abs(ratio * np.exp(np.mean(np.log(q))) - 1) < 0.02), ratio
    assert V == 4


def test_floor_alignment_of_a_tilted_world(ring_scene):
    X = ring_scene.keypoints_world_m[:, ::3].reshape(-1, 23, 3)
    upright = upright_scores(X)
    Q = Rotation.from_euler("xyz", [25, -10, 70], degrees=True).as_matrix()
    shift = np.array([1.0, -2.0, 3.0])
    old = X @ Q.T + shift  # the same people in another frame
    R_cam0 = Q @ ring_scene.rig[0].R_cam_from_world.T  # any rotation; sets the x axis only
    floor = align_to_floor(old, upright, R_cam0.T)
    new = (old - floor.origin_old_m) @ floor.Q_new_from_old.T
    up = floor.Q_new_from_old @ (Q @ [0, 0, 1.0])
    assert np.degrees(np.arccos(up[2])) < 0.3
    assert floor.up_source == "floor_plane"
    soles = new[upright >= 0.5][:, 17:].min(1)[:, 2]
    assert abs(np.median(soles)) < 0.01
    assert np.isclose(np.linalg.det(floor.Q_new_from_old), 1.0)
    with pytest.raises(NoFloorError, match="only 2 people"):
        align_to_floor(old[:2], upright[:2], R_cam0.T)


def _crouching(scene):
    """Every third crouching pose of a scene, (G, 23, 3) world metres."""
    crouch = scene.activity == ACTIVITIES.index("crouch")
    return scene.keypoints_world_m[crouch][::3]


@pytest.fixture(scope="module")
def crouch_scene(body_model):
    from humancal.synthetic import generate_scene, preset

    return generate_scene(preset("demo", num_people=4, num_views=2, num_frames=300, seed=5), body_model,
                          sequence="crouch")


def test_floor_from_people_who_do_not_stand(crouch_scene):
    """No standing person: the foot contacts of crouching people give the floor, the torso axes a coarse up."""
    X = _crouching(crouch_scene)
    score = standing_score(X)
    assert len(X) >= 30 and np.all(score < 0.5)  # nobody stands: the standing path cannot be taken
    Q = Rotation.from_euler("xyz", [25, -10, 70], degrees=True).as_matrix()
    old = X @ Q.T + np.array([1.0, -2.0, 3.0])
    R_cam0 = (Q @ crouch_scene.rig[0].R_cam_from_world.T).T
    floor = align_to_floor(old, score, R_cam0)
    up = floor.Q_new_from_old @ (Q @ [0, 0, 1.0])
    assert floor.up_source == "contact_plane" and floor.standing_groups == 0
    assert np.degrees(np.arccos(up[2])) < 0.3
    new = (old - floor.origin_old_m) @ floor.Q_new_from_old.T
    assert abs(np.median(new[:, 17:, 2].min(1))) < 0.01  # the soles on z = 0
    assert np.isfinite(floor.up_std_deg) and floor.contact_groups >= 0.9 * len(X)

    # all contacts on one spot (one crouch of one person, ankles anchored): no plane; the torso axes give a
    # coarse up
    person, frame = np.argwhere(crouch_scene.activity == ACTIVITIES.index("crouch"))[0]
    run = crouch_scene.activity[person, frame:] == ACTIVITIES.index("crouch")
    length = int(np.argmin(run)) if not run.all() else len(run)
    one = crouch_scene.keypoints_world_m[person, frame:frame + length] @ Q.T + np.array([1.0, -2.0, 3.0])
    assert len(one) >= 30
    coarse = align_to_floor(one, standing_score(one), R_cam0)
    assert coarse.up_source == "torso_axes"
    assert np.degrees(np.arccos((coarse.Q_new_from_old @ (Q @ [0, 0, 1.0]))[2])) < 45.0

    # people tumbling every way give no up direction: a labelled refusal, not a wrong floor
    tumbled = np.einsum("gij,gkj->gki", Rotation.random(len(old), random_state=3).as_matrix(), old)
    with pytest.raises(NoFloorError, match="torso axes point every way"):
        align_to_floor(tumbled, standing_score(tumbled), R_cam0)


def test_similarity_and_rig_alignment(ring_scene):
    rng = np.random.default_rng(1)
    src = rng.normal(size=(10, 3))
    R = Rotation.random(random_state=2).as_matrix()
    sim = fit_similarity(src, 2.5 * src @ R.T + [1, 2, 3])
    assert np.isclose(sim.scale, 2.5) and np.allclose(sim.R, R) and np.allclose(sim.t, [1, 2, 3])
    # a rig moved by a similarity is aligned back exactly and keeps its images
    rig = list(ring_scene.rig)[:2]  # two cameras: optical-axis points fix the baseline rotation
    inv = fit_similarity(np.eye(3), np.eye(3) * 0.5 @ R.T)  # scale 0.5, rotation R, translation 0
    moved = [inv.apply_to_camera(c) for c in rig]
    back = align_rig(moved, rig)
    for m, c in zip(moved, rig):
        a = back.apply_to_camera(m)
        assert np.allclose(a.center_world_m, c.center_world_m, atol=1e-6)
        assert np.allclose(a.R_cam_from_world, c.R_cam_from_world, atol=1e-6)
    X = rng.uniform(-1, 1, size=(5, 3)) + [0, 0, 1]
    assert np.allclose(project_points(moved[0], inv.apply(X))[0], project_points(rig[0], X)[0], atol=1e-6)


def test_standing_score_needs_no_camera(ring_scene):
    """The floor's standing test reads body-internal geometry: any rotation of the world gives the same scores."""
    from humancal.synthetic import ACTIVITIES

    codes = {name: i for i, name in enumerate(ACTIVITIES)}
    X, act = ring_scene.keypoints_world_m.reshape(-1, 23, 3), ring_scene.activity.reshape(-1)
    score = standing_score(X)
    assert score.min() >= 0 and score.max() <= 1
    still = np.isin(act, [codes["stand"], codes["gesture"]])
    moving = np.isin(act, [codes["walk"], codes["crouch"]])
    assert still.any() and moving.any()
    assert score[still].mean() > 0.8 and score[moving].mean() < 0.4
    R = Rotation.from_euler("xyz", [70, 10, 30], degrees=True).as_matrix()  # e.g. a steep camera's frame
    assert np.allclose(standing_score(X @ R.T + 3.0), score)
    broken = X[:2].copy()
    broken[:, 11] = np.nan  # a missing joint: not standing
    assert np.isnan(standing_score(broken)[np.isnan(broken).any((1, 2))]).all()


def test_plot_rigs_writes_a_png(tmp_path, ring_scene):
    rig = list(ring_scene.rig)
    moved = [Camera.from_center(c.K, c.R_cam_from_world, c.center_world_m + 0.1, c.width_px, c.height_px) for c in rig]
    path = plot_rigs(moved, rig, np.random.default_rng(0).uniform(-2, 2, (50, 3)) * [1, 1, 0], tmp_path / "rigs.png")
    assert path.exists() and path.stat().st_size > 10_000
    assert plot_rigs(rig, None, None, tmp_path / "alone.png").exists()
