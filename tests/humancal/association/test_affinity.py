"""Affinity between detections: same-person pairs score higher than others, symmetry, missing joints, wrong
cameras, the temporal term (a small synthetic scene lifted by the shipped lifter)."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import rankdata

from humancal.association import (
    AffinityConfig,
    combine_affinity,
    cross_view_pairs,
    detection_geometry,
    detection_track_affinity,
    pair_affinities,
)
from humancal.camera import CameraRig
from humancal.geometry.alignment import align_points, rigid_residual_rms_m
from humancal.geometry.rotations import axis_angle_to_rotmat
from humancal.tables.detections import DenseDetections


def roc_auc(positive: np.ndarray, score: np.ndarray) -> float:
    """Area under the ROC curve (Mann-Whitney U with ties ranked by their mean)."""
    positive = np.asarray(positive, bool)
    ranks = rankdata(score)
    n1, n0 = positive.sum(), (~positive).sum()
    return float((ranks[positive].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


@pytest.fixture(scope="module")
def scene_inputs(body_model):
    """(detections, lifted, rig, person_id, keypoints_world_m): 3 people, 4 views, 60 frames, shipped lifter."""
    from humancal.lifter import lift_detections, load_lifter, shipped_checkpoint
    from humancal.synthetic import generate_scene, preset
    from humancal.tables.associations import Associations
    from humancal.tables.detections import detections_to_dense

    scene = generate_scene(preset("demo", num_people=3, num_views=4, num_frames=60, seed=11), body_model,
                           sequence="affinity")
    dense = detections_to_dense(scene.detections)
    person = Associations.from_table(scene.associations).person_of_detections(dense)
    rig = CameraRig.from_cameras(scene.rig)
    lifted = lift_detections(load_lifter(shipped_checkpoint()), dense.keypoints_px, dense.scores,
                             K=rig.K[dense.view])
    return dense, lifted, rig, person, scene.keypoints_world_m


def perturbed(rig: CameraRig, focal_pct: float = 3.0, angle_deg: float = 1.0, seed: int = 0) -> CameraRig:
    """Every focal length off by +-focal_pct % and every rotation by angle_deg about a random axis (centres kept)."""
    rng = np.random.default_rng(seed)
    V = len(rig)
    K = rig.K.copy()
    factor = 1.0 + 0.01 * focal_pct * rng.choice([-1.0, 1.0], V)
    K[:, 0, 0] *= factor
    K[:, 1, 1] *= factor
    axis = rng.normal(size=(V, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    R = axis_angle_to_rotmat(axis, np.full(V, np.deg2rad(angle_deg))) @ rig.R_cam_from_world
    t = -np.einsum("vij,vj->vi", R, rig.centers_world_m)
    return CameraRig(K, R, t, rig.distortion, rig.image_size_px)


def pair_aucs(scene_inputs, rig) -> dict[str, float]:
    dense, lifted, _, person, _ = scene_inputs
    out = {}
    for name, config in (("association", AffinityConfig()), ("epipolar_only", AffinityConfig.epipolar_only())):
        pairs = pair_affinities(dense, lifted, rig, config)
        pa, pb = person[pairs.rows_a], person[pairs.rows_b]
        out[name] = roc_auc((pa == pb) & (pa >= 0), pairs.combined)
    return out


# --- accuracy --------------------------------------------------------------------------------------------------

def test_same_person_pairs_score_higher(scene_inputs):
    auc = pair_aucs(scene_inputs, scene_inputs[2])
    # measured: association 0.9981, epipolar_only 0.9977 (docs/results/association.md)
    assert auc["association"] > 0.98, auc
    assert auc["epipolar_only"] > 0.98, auc


def test_wrong_cameras_hurt_the_combined_affinity_less(scene_inputs):
    exact = pair_aucs(scene_inputs, scene_inputs[2])
    wrong = pair_aucs(scene_inputs, perturbed(scene_inputs[2]))
    # measured: association 0.9981 -> 0.9962, epipolar_only 0.9977 -> 0.9883
    assert wrong["association"] > wrong["epipolar_only"], wrong
    assert exact["association"] - wrong["association"] < exact["epipolar_only"] - wrong["epipolar_only"], (exact, wrong)
    assert wrong["association"] > 0.98, wrong


def test_track_affinity_picks_the_right_person(scene_inputs):
    dense, lifted, rig, person, keypoints = scene_inputs
    geometry = detection_geometry(dense, lifted, rig)
    rows = np.flatnonzero((person >= 0) & (dense.frame > 0))
    right = 0
    for frame in np.unique(dense.frame[rows]):
        here = rows[dense.frame[rows] == frame]
        tracks = keypoints[:, frame - 1]  # every person's world joints one frame earlier
        sim = detection_track_affinity(geometry, here, tracks)
        assert sim.shape == (len(here), len(tracks)) and np.isfinite(sim).all()
        assert ((sim >= 0) & (sim <= 1)).all()
        right += (sim.argmax(1) == person[here]).sum()
    assert right / len(rows) > 0.97, right / len(rows)


def test_temporal_term_in_the_frame_matrix(scene_inputs):
    dense, lifted, rig, person, keypoints = scene_inputs
    pairs = pair_affinities(dense, lifted, rig)
    geometry = pairs.geometry
    labels, plain, with_tracks = [], [], []
    for frame in pairs.frames[1:]:
        rows = pairs.frame_rows(frame)
        A = pairs.matrix(frame)
        B = pairs.matrix(frame, detection_track_affinity(geometry, rows, keypoints[:, frame - 1]))
        np.testing.assert_allclose(B, B.T)
        upper = np.triu(pairs.view[rows][:, None] != pairs.view[rows][None], 1)
        p = person[rows]
        labels.append(((p[:, None] == p[None]) & (p[:, None] >= 0))[upper])
        plain.append(A[upper])
        with_tracks.append(B[upper])
    labels = np.concatenate(labels)
    # agreeing with one previous pose separates the pairs better (the tracks here are the true people)
    assert roc_auc(labels, np.concatenate(with_tracks)) >= roc_auc(labels, np.concatenate(plain))
    rows = pairs.frame_rows(10)
    np.testing.assert_array_equal(pairs.matrix(10, np.zeros((len(rows), 0))), pairs.matrix(10))
    with pytest.raises(ValueError, match="track_affinity"):
        pairs.matrix(10, np.zeros((len(rows) + 1, 3)))


# --- structure -------------------------------------------------------------------------------------------------

def test_frame_matrices(scene_inputs):
    dense, lifted, rig, _, _ = scene_inputs
    pairs = pair_affinities(dense, lifted, rig)
    matrices = pairs.matrices()
    assert len(matrices) == len(np.unique(dense.frame))
    for frame, A in zip(pairs.frames, matrices):
        view = dense.view[pairs.frame_rows(frame)]
        assert A.shape == (len(view), len(view))
        np.testing.assert_array_equal(A, A.T)
        np.testing.assert_array_equal(np.diag(A), 1.0)
        same_view = (view[:, None] == view[None]) & ~np.eye(len(view), dtype=bool)
        assert (A[same_view] == 0).all()
        assert ((A >= 0) & (A <= 1)).all()
    assert pairs.matrix(10_000).shape == (0, 0)


def test_symmetric_in_the_order_of_views(scene_inputs):
    dense, lifted, rig, _, _ = scene_inputs
    V = len(rig)
    reversed_rig = CameraRig(rig.K[::-1], rig.R_cam_from_world[::-1], rig.t_cam_from_world_m[::-1],
                             rig.distortion[::-1], rig.image_size_px[::-1])
    new_view = V - 1 - dense.view
    order = np.lexsort((dense.det_id, new_view, dense.frame))
    flipped = DenseDetections(dense.frame[order], new_view[order], dense.det_id[order], dense.keypoints_px[order],
                              dense.scores[order])
    flipped_lifted = lifted.subset(order)
    first = pair_affinities(dense, lifted, rig)
    second = pair_affinities(flipped, flipped_lifted, reversed_rig)
    for frame in first.frames[::7]:
        rows = first.frame_rows(frame)
        back = order[second.frame_rows(frame)]  # original row of each row of the second run
        position = np.argsort(back)
        assert np.array_equal(back[position], rows)
        np.testing.assert_allclose(second.matrix(frame)[np.ix_(position, position)], first.matrix(frame),
                                   atol=1e-5)


def test_cross_view_pairs_against_brute_force():
    rng = np.random.default_rng(3)
    frame = np.sort(rng.integers(0, 6, 40))
    view = rng.integers(0, 3, 40)
    a, b = cross_view_pairs(frame, view)
    expected = {(i, j) for i in range(40) for j in range(i + 1, 40) if frame[i] == frame[j] and view[i] != view[j]}
    assert set(zip(a.tolist(), b.tolist())) == expected and len(a) == len(expected)
    with pytest.raises(ValueError, match="sorted by frame"):
        cross_view_pairs(frame[::-1], view)


def test_rigid_residual_matches_procrustes_alignment():
    rng = np.random.default_rng(0)
    source = rng.normal(size=(200, 23, 3)) * 0.3
    R = axis_angle_to_rotmat(rng.normal(size=(200, 3)), rng.uniform(0, np.pi, 200))
    target = source @ np.swapaxes(R, 1, 2) + rng.normal(size=(200, 1, 3)) + 0.05 * rng.normal(size=(200, 23, 3))
    target[:50, :, 0] *= -1.0  # mirrored targets: the best rotation is not the polar factor
    target[50:60] = rng.normal(size=(10, 23, 3))  # unrelated point sets
    aligned = align_points(source, target, with_scale=False)
    reference = np.sqrt(((aligned - target) ** 2).sum(-1).mean(-1))
    np.testing.assert_allclose(rigid_residual_rms_m(source, target), reference, rtol=1e-6, atol=1e-9)


# --- missing joints --------------------------------------------------------------------------------------------

def _two_views_one_frame(scene_inputs, frame=5):
    dense, lifted, rig, person, _ = scene_inputs
    rows = np.flatnonzero((dense.frame == frame) & (person == 0))[:2]
    assert dense.view[rows[0]] != dense.view[rows[1]]
    pick = DenseDetections(dense.frame[rows], dense.view[rows], dense.det_id[rows], dense.keypoints_px[rows].copy(),
                           dense.scores[rows].copy())
    return pick, lifted.subset(rows), rig


def _without(d: DenseDetections, row: int, joints) -> DenseDetections:
    kp, sc = d.keypoints_px.copy(), d.scores.copy()
    kp[row, joints], sc[row, joints] = np.nan, 0.0
    return replace(d, keypoints_px=kp, scores=sc)


def test_joints_missing_in_one_detection_are_left_out(scene_inputs):
    d, lifted, rig = _two_views_one_frame(scene_inputs)
    missing = np.arange(0, 7)
    one_side = pair_affinities(_without(d, 0, missing), lifted, rig, AffinityConfig.epipolar_only())
    both_sides = pair_affinities(_without(_without(d, 0, missing), 1, missing), lifted, rig,
                                 AffinityConfig.epipolar_only())
    assert np.isfinite(one_side.combined).all() and one_side.combined[0] > 0.5
    np.testing.assert_allclose(one_side.geometric, both_sides.geometric)
    # a NaN pixel with a positive score counts as missing too
    kp = d.keypoints_px.copy()
    kp[0, missing] = np.nan
    nan_only = pair_affinities(replace(d, keypoints_px=kp), lifted, rig, AffinityConfig.epipolar_only())
    np.testing.assert_allclose(nan_only.geometric, one_side.geometric)


def test_no_common_joints_gives_zero_not_nan(scene_inputs):
    d, lifted, rig = _two_views_one_frame(scene_inputs)
    upper, lower = np.arange(0, 11), np.arange(11, 23)
    apart = _without(_without(d, 0, lower), 1, upper)
    for config in (AffinityConfig(), AffinityConfig.epipolar_only()):
        pairs = pair_affinities(apart, lifted, rig, config)
        assert pairs.common_joints[0] == 0
        assert pairs.combined[0] == 0.0 and pairs.geometric[0] == 0.0
        A = pairs.matrix(int(d.frame[0]))
        assert np.isfinite(A).all() and A[0, 1] == 0.0


def test_pose_term_left_out_without_a_lifted_pose(scene_inputs):
    d, lifted, rig = _two_views_one_frame(scene_inputs)
    unlifted = replace(lifted, valid=np.array([True, False]))
    pairs = pair_affinities(d, unlifted, rig)
    assert np.isnan(pairs.pose[0])
    assert pairs.combined[0] == pytest.approx(pairs.geometric[0])
    none = pair_affinities(d, None, rig)
    assert none.combined[0] == pytest.approx(pairs.geometric[0])


def test_combine_affinity_weights():
    config = AffinityConfig(geometric_weight=0.7, pose_weight=0.3)
    out = combine_affinity(np.array([1.0, 0.5, 0.5, 0.9]), np.array([0.0, 0.5, np.nan, 1.0]),
                           np.array([10, 10, 10, 2]), config)
    np.testing.assert_allclose(out, [0.7, 0.5, 0.5, 0.0])


# --- exceptions ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize(
    "field, value",
    [("geometric_weight", -0.1), ("pose_weight", float("nan")), ("ray_distance_scale_m", 0.0),
     ("temporal_scale_m", -1.0), ("min_common_joints", 0), ("depth_scale_range", (1.1, 1.3))],
)
def test_config_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=field):
        AffinityConfig(**{field: value})
    with pytest.raises(ValueError, match="must be > 0"):
        AffinityConfig(geometric_weight=0.0, pose_weight=0.0)


def test_bad_inputs_are_named(scene_inputs):
    dense, lifted, rig, _, _ = scene_inputs
    with pytest.raises(ValueError, match="row-aligned"):
        pair_affinities(dense, lifted.subset(np.arange(3)), rig)
    with pytest.raises(ValueError, match="cameras"):
        pair_affinities(dense, lifted, CameraRig.from_cameras(rig.to_cameras()[:2]))
    geometry = detection_geometry(dense, lifted, rig)
    with pytest.raises(ValueError, match="track_joints_world_m"):
        detection_track_affinity(geometry, np.arange(3), np.zeros((2, 17, 3)))
