import numpy as np

from evaluation.metrics import mpjpe_mm, pa_mpjpe_mm, pcp_correct, similarity_align


def _rot(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def test_mpjpe_counts_valid_joints_only():
    gt = np.zeros((1, 3, 3))
    pred = gt.copy()
    pred[0, 0, 0] = 0.010
    pred[0, 2] = np.nan
    assert np.isclose(mpjpe_mm(pred, gt), 5.0)
    assert np.isclose(mpjpe_mm(pred, gt, valid=np.array([[True, False, True]])), 10.0)


def test_pa_mpjpe_is_invariant_to_similarity_transforms():
    rng = np.random.default_rng(1)
    gt = rng.normal(size=(4, 17, 3))
    pred = gt + rng.normal(scale=0.02, size=gt.shape)
    moved = 1.7 * pred @ _rot(0.8).T + np.array([3.0, -2.0, 1.0])
    assert np.isclose(pa_mpjpe_mm(pred, gt), pa_mpjpe_mm(moved, gt))
    assert pa_mpjpe_mm(moved, gt) < mpjpe_mm(moved, gt)
    assert np.allclose(similarity_align(moved[0], pred[0]), pred[0], atol=1e-9)


def test_pcp_rule_half_limb_length():
    gt = np.array([[[0, 0, 0], [0, 0, 1.0]]])  # limb of length 1 m
    ok = gt + np.array([[[0.4, 0, 0], [0.4, 0, 0]]])  # mean end error 0.4 < 0.5
    bad = gt + np.array([[[0.6, 0, 0], [0.5, 0, 0]]])  # mean end error 0.55
    missing = np.full_like(gt, np.nan)
    limbs = [(0, 1)]
    assert pcp_correct(ok, gt, limbs).tolist() == [[True]]
    assert pcp_correct(bad, gt, limbs).tolist() == [[False]]
    assert pcp_correct(missing, gt, limbs).tolist() == [[False]]


def _poses_table(X: np.ndarray, frames: np.ndarray, person: np.ndarray):
    """A canonical ``poses3d`` table of (N, 23, 3) joints."""
    import pandas as pd

    from humancal.keypoints import CANONICAL_JOINTS

    N, J = X.shape[:2]
    xyz = X.reshape(-1, 3)
    return pd.DataFrame({"sequence": "s", "frame": np.repeat(frames, J).astype(np.int32),
                         "person_id": np.repeat(person, J).astype(np.int32),
                         "joint": np.tile(np.asarray(CANONICAL_JOINTS, dtype=object), N),
                         "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2], "valid": True})


def test_sequence_alignment_removes_the_frame_of_the_world_only():
    """Predictions = truth + 2 cm noise, then moved by one similarity: plain scoring sees the move, the
    sequence-aligned scoring sees only the noise (one fit for the sequence, not one per pose)."""
    from evaluation.protocols import evaluate_canonical_poses

    rng = np.random.default_rng(0)
    truth = rng.normal(0, 0.4, (40, 23, 3)) + [0.0, 0.0, 1.0]
    frames, person = np.repeat(np.arange(20), 2), np.tile([0, 1], 20)
    noisy = truth + rng.normal(0, 0.02, truth.shape)
    moved = 1.05 * noisy @ _rot(0.1).T + [0.3, -0.2, 0.1]
    gt = _poses_table(truth, frames, person)
    plain = {r.metric: r.value for r in evaluate_canonical_poses(_poses_table(moved, frames, person), gt)}
    aligned = {r.metric: r.value for r in evaluate_canonical_poses(_poses_table(moved, frames, person), gt,
                                                                   sequence_aligned=True)}
    assert plain["mpjpe_mm"] > 200
    assert 25 < aligned["mpjpe_mm"] < 40  # the noise: 2 cm per axis, about 32 mm per joint
    assert aligned["pcp_avg"] > plain["pcp_avg"]
