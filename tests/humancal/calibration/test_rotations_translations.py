"""Relative rotations from lifted poses, rotation averaging, root positions, the linear solve and resection."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evaluation.oracle import lift_ground_truth
from humancal.calibration import CalibrationError
from humancal.calibration.rotation_consensus import (
    PairRotation,
    average_rotations,
    pairwise_rotations,
    procrustes_rotations,
)
from humancal.calibration.translations import (
    resect_focal_translation,
    root_positions,
    solve_focals_translations,
)
from humancal.calibration.types import hip_midpoints
from humancal.camera import project_points
from humancal.geometry.rotations import rotation_angle_deg


def test_procrustes_recovers_a_rotation():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(4, 23, 3))
    R = Rotation.random(4, random_state=1).as_matrix()
    dst = np.einsum("mij,mkj->mki", R, src)
    R_est, err = procrustes_rotations(src, dst, np.ones((4, 23)))
    assert np.allclose(R_est, R, atol=1e-9) and np.all(err < 1e-9)


def test_pairwise_rotations_find_the_rig_and_the_people(ring_scene, ring_stand_in):
    d = ring_stand_in.detections
    pairs = pairwise_rotations(d, ring_stand_in.lifted, 4, np.random.default_rng(0))
    assert len(pairs) == 6
    Rg = [c.R_cam_from_world for c in ring_scene.rig]
    for p in pairs:
        truth = Rg[p.view_b] @ Rg[p.view_a].T
        assert rotation_angle_deg(truth.T @ p.R_ba) < 1.5
        same = ring_stand_in.person_id[p.rows_a] == ring_stand_in.person_id[p.rows_b]
        assert same.mean() > 0.9  # identities were unknown: the consensus found the same people
        assert p.support > 20


def _edges(R, noise_deg=0.0, corrupt=(), seed=0):
    rng = np.random.default_rng(seed)
    out = []
    V = len(R)
    for a in range(V):
        for b in range(a + 1, V):
            R_ba = R[b] @ R[a].T
            if noise_deg:
                R_ba = Rotation.from_rotvec(np.radians(noise_deg) * rng.normal(size=3)).as_matrix() @ R_ba
            if (a, b) in corrupt:
                R_ba = Rotation.from_euler("z", 40, degrees=True).as_matrix() @ R_ba
            out.append(PairRotation(a, b, R_ba, np.arange(50), np.arange(50), np.zeros(50), np.zeros(50), 50))
    return out


def test_rotation_averaging_is_robust_to_a_wrong_edge():
    R = Rotation.random(5, random_state=3).as_matrix()
    R = R @ R[0].T
    est, residual = average_rotations(_edges(R, noise_deg=0.3, corrupt={(1, 3)}), 5)
    assert np.allclose(est[0], np.eye(3))
    assert max(rotation_angle_deg(est[v].T @ R[v]) for v in range(5)) < 0.5
    assert np.nanargmax(residual) == [(a, b) for a in range(5) for b in range(a + 1, 5)].index((1, 3))


def test_rotation_averaging_names_a_disconnected_view():
    R = Rotation.random(3, random_state=4).as_matrix()
    edges = [e for e in _edges(R) if 2 not in (e.view_a, e.view_b)]
    with pytest.raises(CalibrationError, match=r"views \[2\]"):
        average_rotations(edges, 3)


def _exact(scene, stand_in):
    d = stand_in.detections
    exact = lift_ground_truth(scene.keypoints_world_m, scene.height_m, scene.rig, d.frame, d.view,
                              stand_in.person_id, np.zeros(len(d), bool), np.random.default_rng(0),
                              joint_noise_m=0.0, height_noise_m=0.0, rotation_noise_deg=0.0, depth_flip_rate=0.0)
    true = stand_in.person_id >= 0
    return exact, true


def test_root_positions_from_exact_poses(ring_scene, ring_stand_in):
    exact, true = _exact(ring_scene, ring_stand_in)
    d = ring_stand_in.detections
    K = np.stack([c.K for c in ring_scene.rig])
    roots = root_positions(d, exact, K)
    hips = hip_midpoints(ring_scene.keypoints_world_m.reshape(-1, 23, 3)).reshape(
        ring_scene.keypoints_world_m.shape[:2] + (3,))
    R = np.stack([c.R_cam_from_world for c in ring_scene.rig])[d.view]
    t = np.stack([c.t_cam_from_world_m for c in ring_scene.rig])[d.view]
    gt = np.einsum("dij,dj->di", R[true], hips[ring_stand_in.person_id[true], d.frame[true]]) + t[true]
    err = np.linalg.norm(roots.T_cam_m[true] - gt, axis=1)
    assert np.nanmedian(err) < 0.03  # 2D noise only
    assert np.allclose(roots.at_focal(np.flatnonzero(true)[:5], 2 * K[d.view[true][:5], 0, 0])[:, 2],
                       2 * roots.T_cam_m[true][:5, 2])


def test_linear_solve_recovers_focal_lengths_and_translations(ring_scene, ring_stand_in):
    exact, true = _exact(ring_scene, ring_stand_in)
    d = ring_stand_in.detections
    K = np.stack([c.K for c in ring_scene.rig])
    f_true = K[:, 0, 0]
    K_wrong = K.copy()
    K_wrong[:, [0, 1], [0, 1]] *= 1.1
    roots = root_positions(d, exact, K_wrong)  # computed at a wrong focal (the principal point kept)
    pairs = pairwise_rotations(d, exact, 4, np.random.default_rng(0))
    ra = np.concatenate([p.rows_a for p in pairs])
    rb = np.concatenate([p.rows_b for p in pairs])
    Rg = np.stack([c.R_cam_from_world for c in ring_scene.rig])
    R = Rg @ Rg[0].T
    sol = solve_focals_translations(roots, d.view, ra, rb, R, 1.1 * f_true, np.full(4, np.inf))
    assert np.all(np.abs(sol.focal_px / f_true - 1) < 0.05)
    same = ring_stand_in.person_id[ra] == ring_stand_in.person_id[rb]
    assert sol.inlier[same].mean() > 0.95 and sol.inlier[~same].mean() < 0.5
    assert np.all(sol.focal_rel_std_data < 0.05)


def test_linear_solve_is_not_biased_by_the_people_sizes(ring_scene, ring_stand_in):
    """A lifter knows body proportions, not size: every person's roots are too far (or near) by one factor.

    Those per-person errors, shared by both roots of a pair, attenuate the focal lengths when left in the
    regressors; the per-pair size correction removes them.
    """
    exact, true = _exact(ring_scene, ring_stand_in)
    d = ring_stand_in.detections
    K = np.stack([c.K for c in ring_scene.rig])
    f_true = K[:, 0, 0]
    # person p appears (1 + e_p) times too large in every view: its roots are that much too far
    size = np.array([0.88, 1.12, 0.93])[np.maximum(ring_stand_in.person_id, 0)]
    roots = root_positions(d, exact, K)
    roots = type(roots)(roots.T_cam_m * size[:, None], roots.zeta_m_per_px * size, roots.rms_px)
    ra, rb = d_pairs = _true_pairs(ring_stand_in)
    Rg = np.stack([c.R_cam_from_world for c in ring_scene.rig])
    R = Rg @ Rg[0].T
    naive = solve_focals_translations(roots, d.view, ra, rb, R, f_true, np.full(4, np.inf), person_scale_std=None)
    sol = solve_focals_translations(roots, d.view, ra, rb, R, f_true, np.full(4, np.inf))
    assert np.max(np.abs(naive.focal_px / f_true - 1)) > 0.1  # the bias the size correction removes
    assert np.all(np.abs(sol.focal_px / f_true - 1) < 0.02), sol.focal_px / f_true
    scale = sol.pair_scale[sol.inlier] * np.sqrt(size[ra] * size[rb])[sol.inlier]  # true / lifted size
    assert np.std(np.log(scale)) < 0.02  # the pairs' corrections follow the people's size errors
    assert sol.inlier.mean() > 0.9 and len(d_pairs[0]) == len(ra)



def test_linear_solve_survives_non_finite_roots(ring_scene, ring_stand_in):
    """A few roots with an infinite depth or position (a degenerate detection) made LAPACK's least squares fail
    ("SVD did not converge"): such pairs are left out and the others still give the focal lengths."""
    exact, true = _exact(ring_scene, ring_stand_in)
    d = ring_stand_in.detections
    K = np.stack([c.K for c in ring_scene.rig])
    f_true = K[:, 0, 0]
    roots = root_positions(d, exact, K)
    ra, rb = _true_pairs(ring_stand_in)
    T, zeta = roots.T_cam_m.copy(), roots.zeta_m_per_px.copy()
    zeta[ra[:3]] = np.inf
    T[rb[5:8], 0] = np.inf
    T[ra[10], 2] = -1e3  # a root far behind the camera gives a negative pair std
    broken = type(roots)(T, zeta, roots.rms_px)
    Rg = np.stack([c.R_cam_from_world for c in ring_scene.rig])
    R = Rg @ Rg[0].T
    sol = solve_focals_translations(broken, d.view, ra, rb, R, f_true, np.full(4, np.inf))
    assert np.isfinite(sol.focal_px).all() and np.isfinite(sol.t_cam_from_world_m).all()
    assert np.all(np.abs(sol.focal_px / f_true - 1) < 0.02), sol.focal_px / f_true
    assert not sol.inlier[:3].any() and not sol.inlier[5:8].any()

def _true_pairs(stand_in):
    """All cross-view pairs of detections of the same true person in the same frame."""
    d, pid = stand_in.detections, stand_in.person_id
    ra, rb = [], []
    rows = np.flatnonzero(pid >= 0)
    key = d.frame[rows] * 1000 + pid[rows]
    for k in np.unique(key):
        r = rows[key == k]
        for i in range(len(r)):
            for j in range(i + 1, len(r)):
                if d.view[r[i]] != d.view[r[j]]:
                    ra.append(r[i])
                    rb.append(r[j])
    return np.array(ra), np.array(rb)


def test_resection_with_known_rotation():
    rng = np.random.default_rng(0)
    R = Rotation.from_euler("xyz", [100, 5, 30], degrees=True).as_matrix()
    t = np.array([0.3, -0.5, 6.0])
    X = rng.uniform([-2, -2, 0], [2, 2, 1.8], size=(200, 3))
    K = np.array([[1300.0, 0, 960], [0, 1300, 540], [0, 0, 1]])
    from humancal.camera import Camera

    px, _ = project_points(Camera(K, R, t, 1920, 1080), X)
    f, t_est, rms = resect_focal_translation(X, px + rng.normal(0, 0.5, px.shape), np.ones(len(X)), R, K[:2, 2])
    assert abs(f / 1300 - 1) < 0.01 and np.linalg.norm(t_est - t) < 0.05 and rms < 1.0
