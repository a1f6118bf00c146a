"""The oracle in place of the lifter (lifted poses from the ground truth): its noise, its score, its place."""

import ast
from pathlib import Path

import numpy as np
import pytest

from evaluation.oracle import lift_ground_truth, stand_in_lifted_poses, upright_scores

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def ring_scene(body_model):
    from humancal.synthetic import generate_scene, preset

    scene_config = preset("demo", num_people=3, num_views=3, num_frames=45, seed=5)
    return generate_scene(scene_config, body_model, sequence="oracle")


@pytest.fixture(scope="module")
def ring_stand_in(ring_scene):
    return stand_in_lifted_poses(ring_scene, np.random.default_rng(0))


def test_stand_in_without_noise_is_the_truth(ring_scene, ring_stand_in):
    d, pid = ring_stand_in.detections, ring_stand_in.person_id
    true = np.flatnonzero(pid >= 0)[:50]
    flipped = np.zeros(len(true), bool)
    lifted = lift_ground_truth(ring_scene.keypoints_world_m, ring_scene.height_m, ring_scene.rig, d.frame[true],
                               d.view[true], pid[true], flipped, np.random.default_rng(0), joint_noise_m=0.0,
                               height_noise_m=0.0, rotation_noise_deg=0.0, depth_flip_rate=0.0)
    cam = ring_scene.rig
    for k, row in enumerate(true):
        X = ring_scene.keypoints_world_m[pid[row], d.frame[row]]
        Xc = X @ cam[d.view[row]].R_cam_from_world.T
        Xc -= 0.5 * (Xc[11] + Xc[12])
        assert np.allclose(lifted.joints_cam_m[k], Xc, atol=1e-9)
    assert np.allclose(lifted.height_m, ring_scene.height_m[pid[true]])
    # noisy stand-in: errors of the requested size
    noisy = ring_stand_in.lifted.joints_cam_m[true]
    err = np.linalg.norm(noisy - lifted.joints_cam_m, axis=-1)
    assert 0.03 < np.median(err) < 0.12


def test_oracle_upright_score_separates_standing_from_crouching(ring_scene, ring_stand_in):
    from humancal.synthetic import ACTIVITIES

    codes = {name: i for i, name in enumerate(ACTIVITIES)}
    X, act = ring_scene.keypoints_world_m, ring_scene.activity
    score = upright_scores(X.reshape(-1, 23, 3)).reshape(act.shape)
    if (act == codes["stand"]).any() and (act == codes["crouch"]).any():
        assert score[act == codes["stand"]].mean() > 0.6 > score[act == codes["crouch"]].mean()
    assert score.min() >= 0 and score.max() <= 1
    # the oracle's lifted poses carry the true pose's score
    d, pid = ring_stand_in.detections, ring_stand_in.person_id
    true = pid >= 0
    expected = score[pid[true], d.frame[true]]
    np.testing.assert_allclose(ring_stand_in.lifted.upright_score[true], expected, atol=1e-12)


def test_the_library_never_imports_the_oracle():
    offenders = []
    for path in sorted((REPO / "humancal").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("evaluation.oracle"):
                offenders.append(str(path.relative_to(REPO)))
            elif isinstance(node, ast.Import) and any(a.name.startswith("evaluation.oracle") for a in node.names):
                offenders.append(str(path.relative_to(REPO)))
    assert not offenders, offenders
    assert not (REPO / "humancal" / "calibration" / "stand_in.py").exists()
