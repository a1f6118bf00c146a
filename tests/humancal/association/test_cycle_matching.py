"""Cycle-consistent matching: recovery, agreement with cvxpy, warm starts, consistency, edge cases."""

import numpy as np
import pytest

from humancal.association.cycle_admm import _Polyhedron, _project_psd, project_capped_simplex, round_batch
from humancal.association.cycle_matching import (
    FrameMatching,
    MatchingConfig,
    WarmStart,
    carry_over,
    clusters_to_matrix,
    match_frame,
    match_frames,
    relaxation_objective,
    round_to_clusters,
    solve_relaxation_cvxpy,
)


def make_frame(rng, people=3, views=4, seen=0.85, false_positives=0.5, noise=0.0, drift=None):
    """A frame from a ground-truth partial permutation: (view (N,), affinity (N, N), person (N,), -1 = false)."""
    view, person = [], []
    for v in range(views):
        here = np.flatnonzero(rng.random(people) < seen)
        fp = rng.poisson(false_positives)
        view += [v] * (len(here) + fp)
        person += here.tolist() + [-1] * fp
    order = rng.permutation(len(view))
    view, person = np.array(view)[order], np.array(person)[order]
    n = len(view)
    same = (person[:, None] == person[None, :]) & (person[:, None] >= 0)
    w = np.where(same, 0.8, 0.2) + noise * (rng.standard_normal((n, n)) if drift is None else drift)
    w = np.triu(np.clip(w, 0.0, 1.0), 1)
    w = w + w.T
    w[view[:, None] == view[None, :]] = 0.0
    np.fill_diagonal(w, 1.0)
    return view, w, person


def truth_clusters(view, person):
    """Ground-truth partition: people seen by at least two views, everyone else -1 (as the matching labels)."""
    out = np.full(len(person), -1)
    for p in np.unique(person[person >= 0]):
        rows = np.flatnonzero(person == p)
        if len(np.unique(view[rows])) >= 2:
            out[rows] = p
    return out


def same_pairs(cluster):
    return (cluster[:, None] == cluster[None, :]) & (cluster[:, None] >= 0) & ~np.eye(len(cluster), dtype=bool)


def check_consistent(view, cluster):
    """Every cluster: ids 0..C-1, at least two detections, at most one per view."""
    ids = np.unique(cluster[cluster >= 0])
    assert (ids == np.arange(len(ids))).all()
    for c in ids:
        rows = np.flatnonzero(cluster == c)
        assert len(rows) >= 2
        assert len(np.unique(view[rows])) == len(rows), f"cluster {c} holds two detections of one view"


# ------------------------------------------------------------------------------------------------------ recovery


@pytest.mark.parametrize("decompose", [True, False])
def test_exact_recovery_on_clean_affinities(decompose):
    rng = np.random.default_rng(0)
    frames = [make_frame(rng, people=rng.integers(1, 6), views=rng.integers(2, 7)) for _ in range(40)]
    result = match_frames([f[0] for f in frames], [f[1] for f in frames], MatchingConfig(decompose=decompose))
    for (view, _, person), m in zip(frames, result):
        assert (same_pairs(m.cluster) == same_pairs(truth_clusters(view, person))).all()
        assert m.converged


def test_recovery_under_noise():
    """Pairwise precision and recall of same-cluster pairs on noisy affinities (noise sigma 0.15: about 2 % of the
    pairs on the wrong side of the threshold), with false positives and people missing from some views."""
    rng = np.random.default_rng(1)
    frames = [make_frame(rng, people=4, views=5, noise=0.15, false_positives=1.0) for _ in range(60)]
    result = match_frames([f[0] for f in frames], [f[1] for f in frames])
    tp = fp = fn = 0
    for (view, _, person), m in zip(frames, result):
        check_consistent(view, m.cluster)
        found, truth = same_pairs(m.cluster), same_pairs(truth_clusters(view, person))
        tp, fp, fn = tp + (found & truth).sum(), fp + (found & ~truth).sum(), fn + (~found & truth).sum()
    precision, recall = tp / (tp + fp), tp / (tp + fn)
    assert precision >= 0.97 and recall >= 0.97, (precision, recall)
    # Pairs above the threshold alone are less precise: the cycle-consistent program earns its keep.
    tp_t = fp_t = 0
    for view, w, person in frames:
        link = (w > 0.5) & (view[:, None] != view[None, :])
        truth = same_pairs(truth_clusters(view, person))
        tp_t, fp_t = tp_t + (link & truth).sum(), fp_t + (link & ~truth).sum()
    assert precision > tp_t / (tp_t + fp_t)


def test_batched_frames_equal_single_frames():
    rng = np.random.default_rng(2)
    frames = [make_frame(rng, noise=0.2) for _ in range(12)] + [(np.zeros(0, int), np.zeros((0, 0)), None)]
    batched = match_frames([f[0] for f in frames], [f[1] for f in frames])
    for (view, w, _), m in zip(frames, batched):
        single = match_frame(view, w)
        assert (single.cluster == m.cluster).all()
        np.testing.assert_allclose(single.relaxed, m.relaxed, atol=1e-12)


# ------------------------------------------------------------------------------------------------ cvxpy reference


def test_admm_agrees_with_cvxpy():
    """Same relaxation, two solvers: the objective agrees and the rounded clusters are the same, on instances with
    noise, false positives and people missing from views (N <= 12)."""
    rng = np.random.default_rng(3)
    cases, solved = 0, 0
    while cases < 6:
        view, w, _ = make_frame(rng, people=rng.integers(2, 4), views=rng.integers(3, 5), noise=0.2,
                                false_positives=0.7)
        if not 5 <= len(view) <= 12:
            continue
        cases += 1
        config = MatchingConfig(tolerance=1e-4)
        reference = solve_relaxation_cvxpy(view, w, config)
        f_ref = relaxation_objective(view, w, reference, config)
        for decompose in (False, True):
            m = match_frame(view, w, MatchingConfig(tolerance=1e-4, decompose=decompose))
            assert m.objective == pytest.approx(f_ref, abs=2e-3 + 1e-3 * abs(f_ref))
            assert (m.cluster == round_to_clusters(reference, view)).all()
            solved += m.iterations > 0
    assert solved >= 6  # the ADMM itself ran, not only the exact shortcuts


def test_objective_of_a_partial_permutation():
    view = np.array([0, 1, 2, 0])
    w = np.zeros((4, 4))
    w[0, 1] = w[1, 0] = 0.9
    w[1, 2] = w[2, 1] = 0.7
    w[0, 2] = w[2, 0] = 0.8
    x = clusters_to_matrix(np.array([0, 0, 0, -1]))
    config = MatchingConfig(match_threshold=0.5, low_rank_weight=0.1)
    assert relaxation_objective(view, w, x, config) == pytest.approx(0.4 + 0.2 + 0.3 - 0.4)


# ----------------------------------------------------------------------------------------------------- warm start


def test_warm_start_reduces_iterations():
    rng = np.random.default_rng(4)
    drift = rng.standard_normal((40, 40))
    state = np.random.default_rng(5)
    view, w0, person = make_frame(state, people=4, views=5, noise=0.0)
    n = len(view)
    config = MatchingConfig(decompose=False)
    cold, warm, previous = [], [], None
    for _ in range(15):
        drift = 0.9 * drift + np.sqrt(1 - 0.81) * rng.standard_normal(drift.shape)
        w = np.triu(np.clip(w0 + 0.15 * drift[:n, :n], 0, 1), 1)
        w = w + w.T
        w[view[:, None] == view[None, :]] = 0.0
        np.fill_diagonal(w, 1.0)
        start = None if previous is None else carry_over(previous, np.arange(n))
        previous = match_frame(view, w, config, start)
        if start is not None:
            warm.append(previous.iterations)
            cold.append(match_frame(view, w, config).iterations)
            assert (previous.cluster == match_frame(view, w, config).cluster).all()
    assert np.mean(cold) > 0
    assert np.mean(warm) <= 0.7 * np.mean(cold), (warm, cold)


def test_carry_over_maps_rows():
    previous = FrameMatching(np.array([0, 0, -1]), np.array([[1, .9, 0], [.9, 1, .1], [0, .1, 1.]]),
                             np.arange(9.0).reshape(3, 3), 0.0, 1, True)
    warm = carry_over(previous, np.array([1, -1, 0]))
    np.testing.assert_allclose(warm.relaxed, [[1, 0, .9], [0, 1, 0], [.9, 0, 1]])
    np.testing.assert_allclose(warm.dual, [[4, 0, 3], [0, 0, 0], [1, 0, 0]])
    with pytest.raises(ValueError, match="rows"):
        carry_over(previous, np.array([3]))


# ---------------------------------------------------------------------------------------------- cycle consistency


def test_cycle_consistency_on_adversarial_affinities():
    """Uniform random affinities (no structure at all) still give clusters with one detection per view at most."""
    rng = np.random.default_rng(6)
    views, affinities = [], []
    for _ in range(60):
        n = int(rng.integers(2, 25))
        view = rng.integers(0, rng.integers(1, 6), n)
        w = np.triu(rng.random((n, n)), 1)
        views.append(view)
        affinities.append(w + w.T + np.eye(n))
    for config in (MatchingConfig(), MatchingConfig(decompose=False), MatchingConfig(max_iterations=3),
                   MatchingConfig(match_threshold=0.1)):
        for view, m in zip(views, match_frames(views, affinities, config)):
            check_consistent(view, m.cluster)
            assert np.allclose(np.diag(m.relaxed), 1.0) and (m.relaxed >= 0).all() and (m.relaxed <= 1).all()


def test_rounding_prefers_the_cluster_with_most_views():
    """A linked group with a view conflict (detections 0 and 4 share view 0) splits into the 4-view cluster first."""
    view = np.array([0, 1, 2, 3, 0, 4])
    x = np.eye(6)
    for a, b in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3), (4, 5), (4, 3)]:
        x[a, b] = x[b, a] = 0.9
    cluster = round_to_clusters(x, view)
    assert (cluster == [0, 0, 0, 0, 1, 1]).all()
    check_consistent(view, cluster)


def test_blockwise_projection_matches_reference():
    rng = np.random.default_rng(7)
    view = np.array([[0, 1, 1, 2, 2, 2, 3, 3]])
    z = rng.normal(0.4, 0.8, (1, 8, 8))
    y = _Polyhedron(view, np.ones((1, 8), bool))(z)
    for a in range(8):
        assert y[0, a, a] == 1.0
        for v in range(4):
            cols = np.flatnonzero(view[0] == v)
            expected = 0.0 if v == view[0, a] else project_capped_simplex(z[0, a, cols][None])[0]
            np.testing.assert_allclose(y[0, a, cols[cols != a]], np.broadcast_to(expected, cols.shape)[cols != a],
                                       atol=1e-12)
    # a batch of problems with their views in any order, one of them with a padding detection, and a subset of it
    views = np.stack([rng.permutation(view[0]) for _ in range(3)])
    real = np.ones((3, 8), bool)
    real[1, 5] = False
    z = rng.normal(0.4, 0.8, (3, 8, 8))
    polyhedron = _Polyhedron(views, real)
    for keep, out in ((np.ones(3, bool), polyhedron(z)), (np.array([False, True, True]),
                                                          polyhedron.subset(np.array([False, True, True]))(z[1:]))):
        for p, problem in enumerate(np.flatnonzero(keep)):
            for a in range(8):
                for v in range(4):
                    cols = np.flatnonzero((views[problem] == v) & real[problem] & (np.arange(8) != a))
                    if v == views[problem, a] or not real[problem, a]:
                        np.testing.assert_array_equal(out[p, a, cols], 0.0)
                    else:
                        expected = project_capped_simplex(z[problem, a, cols][None])[0]
                        np.testing.assert_allclose(out[p, a, cols], expected, atol=1e-12)
    # The reference is a projection: the residual makes an obtuse angle with every feasible direction.
    p = project_capped_simplex(z[0, :, :4])
    for q in rng.dirichlet(np.ones(5), 200)[:, :4]:
        assert (((z[0, :, :4] - p) * (q - p)).sum(axis=1) <= 1e-9).all()


@pytest.mark.parametrize("shift", [-0.5, 0.5])  # mostly negative eigenvalues, mostly positive ones
def test_psd_projection_clips_the_eigenvalues_from_either_side(shift):
    rng = np.random.default_rng(3)
    a = rng.normal(size=(4, 12, 12))
    m = 0.5 * (a + a.transpose(0, 2, 1)) / 3.0 + shift * np.eye(12)
    w, q = np.linalg.eigh(m)
    assert ((w > 0).any(axis=1) & (w < 0).any(axis=1)).all()  # both sides in every matrix: not trivial
    expected = (q * np.maximum(w, 0.0)[:, None, :]) @ q.transpose(0, 2, 1)
    np.testing.assert_allclose(_project_psd(m), expected, atol=1e-12)


# ----------------------------------------------------------------------------------------------------- edge cases


def test_edge_cases():
    empty = match_frame(np.zeros(0, np.int64), np.zeros((0, 0)))
    assert empty.cluster.shape == (0,) and empty.relaxed.shape == (0, 0) and empty.iterations == 0
    one = match_frame(np.array([3]), np.ones((1, 1)))
    assert (one.cluster == [-1]).all()
    # All detections from one view: nobody can be matched.
    single_view = match_frame(np.array([2, 2, 2]), np.full((3, 3), 0.9))
    assert (single_view.cluster == -1).all() and np.allclose(single_view.relaxed, np.eye(3))
    # Two views, one detection each: matched exactly when the pair is above the threshold.
    assert (match_frame(np.array([0, 1]), np.array([[1, .7], [.7, 1]])).cluster == [0, 0]).all()
    assert (match_frame(np.array([0, 1]), np.array([[1, .3], [.3, 1]])).cluster == [-1, -1]).all()
    # Frames without people next to frames with people.
    rng = np.random.default_rng(8)
    view, w, person = make_frame(rng)
    out = match_frames([np.zeros(0, int), view, np.array([0])], [np.zeros((0, 0)), w, np.eye(1)])
    assert len(out[0].cluster) == 0 and (out[2].cluster == -1).all()
    assert (same_pairs(out[1].cluster) == same_pairs(truth_clusters(view, person))).all()


def test_nan_affinities_count_as_zero():
    rng = np.random.default_rng(9)
    view, w, _ = make_frame(rng, noise=0.1)
    holes = np.triu(rng.random(w.shape) < 0.2, 1)
    holes = holes | holes.T
    with_nan = np.where(holes, np.nan, w)
    a, b = match_frame(view, with_nan), match_frame(view, np.where(holes, 0.0, w))
    assert (a.cluster == b.cluster).all()
    np.testing.assert_allclose(a.relaxed, b.relaxed)
    assert np.isfinite(a.objective)
    assert (match_frame(np.array([0, 1, 2]), np.full((3, 3), np.nan)).cluster == -1).all()


def test_bad_input_is_refused():
    view = np.array([0, 1])
    with pytest.raises(ValueError, match="shape"):
        match_frame(view, np.eye(3))
    with pytest.raises(ValueError, match="symmetric"):
        match_frame(view, np.array([[1, .9], [.1, 1]]))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        match_frame(view, np.array([[1, 2.0], [2.0, 1]]))
    with pytest.raises(ValueError, match="integer"):
        match_frame(np.array([0.0, 1.0]), np.eye(2))
    with pytest.raises(ValueError, match="one entry per frame"):
        match_frames([view], [])
    with pytest.raises(ValueError, match="warm_start.relaxed"):
        match_frame(view, np.eye(2), warm_start=WarmStart(np.eye(3)))
    for field, value in [("match_threshold", 1.5), ("rho", 0.0), ("tolerance", -1.0), ("max_iterations", 0),
                         ("rounding_threshold", 0.4), ("over_relaxation", 2.0), ("low_rank_weight", -1.0)]:
        with pytest.raises(ValueError, match=field):
            MatchingConfig(**{field: value})


def test_round_batch_on_padding_leaves_it_alone():
    x = np.zeros((1, 4, 4))
    x[0] = np.eye(4)
    x[0, 0, 1] = x[0, 1, 0] = 0.95
    first = round_batch(x, np.array([[0, 1, 7, 8]]), 0.5)
    assert (first == [[0, 0, -1, -1]]).all()
