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
