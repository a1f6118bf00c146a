"""Cycle-consistent matching of the detections of one frame across views (a partial permutation).

The detections of a frame (N of them, each with a view label) and their pairwise affinities W (N, N) in [0, 1]
give a relaxed correspondence matrix X (N, N), solved as a convex program:

    maximise   sum over pairs a < b in different views of (W_ab - threshold) * X_ab  -  low_rank_weight * ||X||_*
    subject to X positive semidefinite, 0 <= X <= 1, X_aa = 1, X_ab = 0 when a != b share a view,
               sum of X_ab over the detections b of any one view <= 1 (for every row a).

The 0/1 points of the feasible set are exactly the partial permutations (clusterings with at most one detection
per view per cluster: X_ab = 1 inside a cluster, 0 elsewhere): a symmetric 0/1 matrix with a unit diagonal is
positive semidefinite exactly when "matched" is transitive (a with b and b with c makes a with c), so the cone is
the convex form of cycle consistency (Huang & Guibas 2013; MatchALS, Zhou et al. 2015; Dong et al. 2019 use this
program for people across views). A pair gains its affinity minus the threshold, so pairs below the threshold are
matched only when consistency demands it. With a unit diagonal the nuclear norm of a positive semidefinite X is
its trace, N, so the low-rank term does not move the optimum; inside the solver it shrinks the eigenvalues of every
iterate towards low rank.

The solver is our own ADMM (:mod:`humancal.association.cycle_admm`), vectorised over many problems at once
(numpy's batched ``eigh``): X in the positive semidefinite cone, a copy Y in the polyhedron of the linear
constraints (row by row and view by view onto ``{y >= 0, sum y <= 1}``), residual balancing of the penalty. It
starts from a warm start (the previous frame's relaxed matrix and dual carried over to this frame's detections,
:func:`carry_over`) or from the identity. The program splits exactly over the connected parts of the graph of
pairs above the threshold (pairs across parts gain nothing from being matched, and every principal block of a
feasible X is feasible); parts of all frames are solved together, padded to a few sizes. Two kinds of part need
no solver: one detection per view and no pair below the threshold (the optimum is all ones), and no pair above it
(the identity).

Rounding links the pairs with X_ab > 0.5 (at most one per view and row, by the row sums). A linked group is a
cluster when its views are distinct and every member's mean relaxed value to the others exceeds 0.5; any other
group is split greedily, the candidate cluster with the most corresponding views first. Detections left alone are
unmatched (-1): false positives or people seen by one view only. :func:`solve_relaxation_cvxpy` solves the same
program with cvxpy (SCS) as a reference on small cases.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import threadpoolctl
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from humancal.association.cycle_admm import round_batch, solve_batch

__all__ = [
    "FrameMatching",
    "MatchingConfig",
    "WarmStart",
    "carry_over",
    "clusters_to_matrix",
    "match_frame",
    "match_frames",
    "relaxation_objective",
    "round_to_clusters",
    "solve_relaxation_cvxpy",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class MatchingConfig:
    """Settings of the relaxation, its ADMM solver and the rounding.

    Attributes:
        match_threshold: affinity a pair must exceed to gain from being matched (the objective adds
            ``affinity - match_threshold`` per matched pair), in [0, 1].
        low_rank_weight: weight of the nuclear-norm (low-rank) penalty, >= 0 (see the module docstring).
        rho: initial ADMM penalty, > 0; adapted by residual balancing.
        over_relaxation: ADMM over-relaxation factor in [1, 2) (1: plain ADMM).
        tolerance: stop when the primal and dual residuals per matrix entry (Frobenius norm / N) are both below it.
        max_iterations: iteration cap per problem.
        rounding_threshold: relaxed value above which a pair is joined when rounding, in [0.5, 1) (0.5 or more
            keeps at most one partner per view and row).
        decompose: solve the connected parts of the pairs above ``match_threshold`` separately (exact; faster).
    """

    match_threshold: float = 0.5
    low_rank_weight: float = 0.05
    rho: float = 0.5
    over_relaxation: float = 1.0
    tolerance: float = 1e-3
    max_iterations: int = 300
    rounding_threshold: float = 0.5
    decompose: bool = True

    def __post_init__(self) -> None:
        if not 0.0 <= self.match_threshold <= 1.0:
            raise ValueError(f"MatchingConfig.match_threshold must lie in [0, 1], got {self.match_threshold}")
        if not self.low_rank_weight >= 0.0:
            raise ValueError(f"MatchingConfig.low_rank_weight must be >= 0, got {self.low_rank_weight}")
        if not self.rho > 0.0:
            raise ValueError(f"MatchingConfig.rho must be > 0, got {self.rho}")
        if not 1.0 <= self.over_relaxation < 2.0:
            raise ValueError(f"MatchingConfig.over_relaxation must lie in [1, 2), got {self.over_relaxation}")
        if not self.tolerance > 0.0:
            raise ValueError(f"MatchingConfig.tolerance must be > 0, got {self.tolerance}")
        if self.max_iterations < 1:
            raise ValueError(f"MatchingConfig.max_iterations must be >= 1, got {self.max_iterations}")
        if not 0.5 <= self.rounding_threshold < 1.0:
            raise ValueError(f"MatchingConfig.rounding_threshold must lie in [0.5, 1), got {self.rounding_threshold}")


@dataclass(frozen=True)
class WarmStart:
    """A starting point for the solver on one frame.

    Attributes:
        relaxed: (N, N) relaxed correspondence matrix (e.g. the previous frame's, carried over).
        dual: (N, N) ADMM dual of the linear constraints (unscaled), or None to start it at zero.
    """

    relaxed: np.ndarray
    dual: np.ndarray | None = None


@dataclass(frozen=True)
class FrameMatching:
    """The matching of one frame.

    Attributes:
        cluster: (N,) int64 cluster (person within the frame) of every detection, 0..C-1 ordered by their first
            detection, or -1 when unmatched; a cluster holds at least two detections, from different views.
        relaxed: (N, N) float64 relaxed correspondence matrix (symmetric, unit diagonal, entries in [0, 1]).
        dual: (N, N) float64 ADMM dual at the end (for warm starts; zero where nothing was solved).
        objective: value of the relaxation's objective at ``relaxed``.
        iterations: ADMM iterations of the slowest part of the frame (0 when nothing needed solving).
        converged: whether every part met the tolerance before the iteration cap.
    """

    cluster: np.ndarray
    relaxed: np.ndarray
    dual: np.ndarray
    objective: float
    iterations: int
    converged: bool

    def warm_start(self, rows: np.ndarray) -> WarmStart:
        """This solution carried over to another frame's detections (see :func:`carry_over`)."""
        return carry_over(self, rows)


def carry_over(previous: FrameMatching, rows: np.ndarray) -> WarmStart:
    """Map a frame's solution to the detections of the next frame.

    Args:
        previous: the previous frame's matching (N_prev detections).
        rows: (N,) int, for each detection of the new frame the row of the previous frame's detection it continues
            (same person, same view), or -1 for a new one.

    Returns:
        WarmStart with (N, N) matrices: the previous entries between continued detections, the identity elsewhere
        (zero dual).
    """
    rows = np.asarray(rows).reshape(-1)
    n_prev = len(previous.cluster)
    if rows.size and (not np.issubdtype(rows.dtype, np.integer) or rows.min() < -1 or rows.max() >= n_prev):
        raise ValueError(f"rows must hold integers in [-1, {n_prev}), got {rows[:8]}")
    known = rows >= 0
    both = known[:, None] & known[None, :]
    relaxed = np.where(both, previous.relaxed[np.ix_(np.maximum(rows, 0), np.maximum(rows, 0))], 0.0)
    dual = np.where(both, previous.dual[np.ix_(np.maximum(rows, 0), np.maximum(rows, 0))], 0.0)
    np.fill_diagonal(relaxed, 1.0)
    return WarmStart(relaxed, dual)


def clusters_to_matrix(cluster: np.ndarray) -> np.ndarray:
    """The (N, N) 0/1 correspondence matrix of a clustering (ones inside each cluster and on the diagonal).

    Args:
        cluster: (N,) int cluster id of every detection, -1 for unmatched.
    """
    cluster = np.asarray(cluster).reshape(-1)
    x = ((cluster[:, None] == cluster[None, :]) & (cluster[:, None] >= 0)).astype(np.float64)
    np.fill_diagonal(x, 1.0)
    return x


def _check_frame(view: np.ndarray, affinity: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Validated (N,) int64 views and (N, N) float64 affinities (NaN -> 0)."""
    view = np.asarray(view)
    if view.ndim != 1:
        raise ValueError(f"{name}: view must have shape (N,), got {view.shape}")
    if view.size and not np.issubdtype(view.dtype, np.integer):
        raise ValueError(f"{name}: view must hold integer view labels, got dtype {view.dtype}")
    n = len(view)
    affinity = np.asarray(affinity, dtype=np.float64)
    if affinity.shape != (n, n):
        raise ValueError(f"{name}: affinity must have shape ({n}, {n}) for {n} detections, got {affinity.shape}")
    nan = np.isnan(affinity)
    if nan.any():
        logger.debug("%s: %d NaN affinities treated as 0", name, int(nan.sum()))
        affinity = np.where(nan, 0.0, affinity)
    if affinity.size and (affinity.min() < -1e-9 or affinity.max() > 1 + 1e-9):
        raise ValueError(f"{name}: affinity must lie in [0, 1] (or NaN), got [{affinity.min()}, {affinity.max()}]")
    asymmetry = np.abs(affinity - affinity.T).max() if n else 0.0
    if asymmetry > 1e-6:
        raise ValueError(f"{name}: affinity must be symmetric, got max |W - W.T| = {asymmetry}")
    return view.astype(np.int64), np.clip(affinity, 0.0, 1.0)


def relaxation_objective(view: np.ndarray, affinity: np.ndarray, relaxed: np.ndarray,
                         config: MatchingConfig = MatchingConfig()) -> float:
    """The relaxation's objective (to maximise) at a correspondence matrix.

    Args:
        view: (N,) int view of every detection.
        affinity: (N, N) symmetric affinities in [0, 1]; NaN counts as 0.
        relaxed: (N, N) correspondence matrix.
        config: the threshold and low-rank weight.

    Returns:
        sum over pairs a < b in different views of (W_ab - threshold) X_ab, minus low_rank_weight * trace(X).
    """
    view, affinity = _check_frame(view, affinity, "relaxation_objective")
    relaxed = np.asarray(relaxed, dtype=np.float64)
    free = view[:, None] != view[None, :]
    gain = np.where(free, affinity - config.match_threshold, 0.0)
    return float(0.5 * (gain * relaxed).sum() - config.low_rank_weight * np.trace(relaxed))


# ------------------------------------------------------------------------------------------------- frames, parts


def _flat_index(offset: np.ndarray, size: np.ndarray, local: np.ndarray) -> np.ndarray:
    """(P, n, n) indices into frames' (N_f, N_f) matrices stored flat one after another, for members (P, n)."""
    return offset[:, None, None] + local[:, :, None] * size[:, None, None] + local[:, None, :]


def match_frames(views: Sequence[np.ndarray], affinities: Sequence[np.ndarray],
                 config: MatchingConfig = MatchingConfig(),
                 warm_starts: Sequence[WarmStart | None] | None = None) -> list[FrameMatching]:
    """Match the detections of many frames; the problems of all frames are solved together in batches.

    Args:
        views: per frame, (N_f,) int view label of every detection.
        affinities: per frame, (N_f, N_f) symmetric affinities in [0, 1]; NaN counts as 0; the diagonal and the
            entries between detections of one view are ignored.
        config: relaxation, solver and rounding settings.
        warm_starts: per frame a :class:`WarmStart` with (N_f, N_f) matrices, or None (start at the identity).

    Returns:
        One :class:`FrameMatching` per frame.

    Raises:
        ValueError: mismatched lengths or shapes, non-integer views, affinities outside [0, 1] or not symmetric.
    """
    if len(views) != len(affinities):
        raise ValueError(f"views and affinities must have one entry per frame, got {len(views)} and {len(affinities)}")
    if warm_starts is not None and len(warm_starts) != len(views):
        raise ValueError(f"warm_starts must have one entry per frame ({len(views)}), got {len(warm_starts)}")
    frames = [_check_frame(v, a, f"frame {i}") for i, (v, a) in enumerate(zip(views, affinities))]
    size = np.array([len(v) for v, _ in frames], dtype=np.int64)
    det_offset = np.concatenate([[0], np.cumsum(size)]).astype(np.int64)
    mat_offset = np.concatenate([[0], np.cumsum(size**2)]).astype(np.int64)
    total = int(det_offset[-1])
    frame_of = np.repeat(np.arange(len(frames)), size)
    local = np.arange(total) - det_offset[frame_of]
    view = np.concatenate([v for v, _ in frames]) if total else np.zeros(0, np.int64)
    affinity = np.concatenate([a.reshape(-1) for _, a in frames]) if total else np.zeros(0)
    start, dual = _flat_starts(warm_starts, size, mat_offset)

    labels = _parts(frames, det_offset, frame_of, config) if total else np.zeros(0, np.int64)
    relaxed, dual_out = _flat_identity(size, mat_offset), np.zeros_like(dual)
    first = np.full(total, -1, dtype=np.int64)  # global row of the first detection of each detection's cluster
    iterations = np.zeros(len(frames), np.int64)
    converged = np.ones(len(frames), bool)
    with _blas_controller().limit(limits=1, user_api="blas"):
        # Many small matrices: one BLAS thread is fastest, and threads fight over busy cores.
        for members in _buckets(labels, view):
            real = members >= 0
            rows = np.where(real, members, members[:, :1])
            pf = frame_of[rows[:, 0]]
            index = _flat_index(mat_offset[pf], size[pf], local[rows])
            pair = real[:, :, None] & real[:, None, :]
            # Padding detections get views of their own, above every real view.
            v = np.where(real, view[rows], view.max() + 1 + np.arange(members.shape[1]))
            free = pair & (v[:, :, None] != v[:, None, :])
            gain = np.where(free, affinity[index] - config.match_threshold, 0.0)
            # Exact without solving: one detection per view and no losing pair (everyone matched: all ones), or
            # no gaining pair (no one matched: the identity).
            shared = (pair & ~free).sum(axis=(1, 2)) > real.sum(axis=1)
            clique = ~shared & ((gain >= 0.0) | ~free).all(axis=(1, 2))
            alone = ((gain <= 0.0) | ~free).all(axis=(1, 2))
            x = np.where(clique[:, None, None], pair, np.eye(members.shape[1], dtype=bool)).astype(np.float64)
            d = np.zeros_like(x)
            hard = ~clique & ~alone
            if hard.any():
                x[hard], d[hard], its, ok = solve_batch(
                    gain[hard], v[hard], real[hard], start[index[hard]] * pair[hard], dual[index[hard]] * pair[hard],
                    rho=config.rho, low_rank_weight=config.low_rank_weight, over_relaxation=config.over_relaxation,
                    tolerance=config.tolerance, max_iterations=config.max_iterations)
                np.maximum.at(iterations, pf[hard], its)
                np.logical_and.at(converged, pf[hard], ok)
            relaxed[index[pair]], dual_out[index[pair]] = x[pair], d[pair]
            rep = round_batch(x, v, config.rounding_threshold)
            took = real & (rep >= 0)
            first[members[took]] = np.take_along_axis(members, np.maximum(rep, 0), axis=1)[took]
    if not converged.all():
        logger.debug("cycle matching: %d of %d frames hit the iteration cap (%d)", int((~converged).sum()),
                     len(frames), config.max_iterations)
    cluster = _number_clusters(first, det_offset, frame_of)
    out = []
    for f, (v, a) in enumerate(frames):
        n = int(size[f])
        x = relaxed[mat_offset[f]:mat_offset[f + 1]].reshape(n, n)
        gain = np.where(v[:, None] != v[None, :], a - config.match_threshold, 0.0)
        objective = float(0.5 * (gain * x).sum() - config.low_rank_weight * np.trace(x))
        out.append(FrameMatching(cluster[det_offset[f]:det_offset[f + 1]], x,
                                 dual_out[mat_offset[f]:mat_offset[f + 1]].reshape(n, n), objective,
                                 int(iterations[f]), bool(converged[f])))
    return out


def match_frame(view: np.ndarray, affinity: np.ndarray, config: MatchingConfig = MatchingConfig(),
                warm_start: WarmStart | None = None) -> FrameMatching:
    """Match the detections of one frame across views (see :func:`match_frames` and the module docstring).

    Args:
        view: (N,) int view label of every detection.
        affinity: (N, N) symmetric affinities in [0, 1]; NaN counts as 0.
        config: relaxation, solver and rounding settings.
        warm_start: starting point (e.g. the previous frame's solution, :func:`carry_over`), or None (identity).

    Returns:
        The frame's :class:`FrameMatching`.
    """
    return match_frames([view], [affinity], config, [warm_start])[0]


@functools.cache
def _blas_controller() -> threadpoolctl.ThreadpoolController:
    """The BLAS libraries, inspected once (a fresh ``threadpool_limits`` costs ~0.4 ms per call)."""
    return threadpoolctl.ThreadpoolController()


def _buckets(labels: np.ndarray, view: np.ndarray) -> list[np.ndarray]:
    """The problems worth solving, grouped by padded size: per bucket (P, m) global rows (increasing, -1 padding).

    A problem is worth solving when it holds detections of two views or more; sizes are padded up to 3, 4, 6, 8,
    12, 16, ... so that few batches (few Python loops) carry all problems.
    """
    if not labels.size:
        return []
    order = np.argsort(labels, kind="stable")
    counts = np.bincount(labels)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    lo = np.minimum.reduceat(view[order], starts[counts > 0]) if order.size else np.zeros(0)
    hi = np.maximum.reduceat(view[order], starts[counts > 0]) if order.size else np.zeros(0)
    multi = np.zeros(len(counts), bool)
    multi[counts > 0] = lo != hi
    sizes = np.unique(np.r_[2, 3, 2 ** np.arange(2, 12), 3 * 2 ** np.arange(1, 11)])
    padded = sizes[np.searchsorted(sizes, counts)] if counts.size else counts
    out = []
    for m in np.unique(padded[multi & (counts >= 2)]).tolist():
        parts = np.flatnonzero(multi & (counts >= 2) & (padded == m))
        slot = np.arange(m)[None, :]
        rows = np.where(slot < counts[parts, None], starts[parts, None] + slot, -1)
        out.append(np.where(rows >= 0, order[np.maximum(rows, 0)], -1))
    return out


def _flat_starts(warm_starts, size: np.ndarray, mat_offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starting matrices and duals of all frames, flat one after another (identity and zeros by default)."""
    start = _flat_identity(size, mat_offset)
    dual = np.zeros_like(start)
    for f, warm in enumerate(warm_starts or ()):
        if warm is None:
            continue
        n = int(size[f])
        for name, m in (("relaxed", warm.relaxed), ("dual", warm.dual)):
            if m is not None and np.shape(m) != (n, n):
                raise ValueError(f"frame {f}: warm_start.{name} must have shape ({n}, {n}), got {np.shape(m)}")
        start[mat_offset[f]:mat_offset[f + 1]] = np.nan_to_num(np.asarray(warm.relaxed, np.float64)).reshape(-1)
        if warm.dual is not None:
            dual[mat_offset[f]:mat_offset[f + 1]] = np.nan_to_num(np.asarray(warm.dual, np.float64)).reshape(-1)
    return start, dual


def _number_clusters(first: np.ndarray, det_offset: np.ndarray, frame_of: np.ndarray) -> np.ndarray:
    """(total,) cluster ids 0..C-1 within each frame, ordered by their first detection; -1 stays -1."""
    is_first = first == np.arange(len(first))
    rank = np.cumsum(is_first) - 1
    rank = rank - (rank[det_offset[frame_of]] - is_first[det_offset[frame_of]] + 1)
    return np.where(first >= 0, rank[np.maximum(first, 0)], -1).astype(np.int64)


def _flat_identity(size: np.ndarray, mat_offset: np.ndarray) -> np.ndarray:
    flat = np.zeros(int(mat_offset[-1]))
    for f, n in enumerate(size.tolist()):
        flat[mat_offset[f]:mat_offset[f + 1]:n + 1] = 1.0
    return flat


def _parts(frames, det_offset, frame_of, config) -> np.ndarray:
    """(total,) label of the independent problem of every detection: its frame, or (``decompose``) the connected
    part of the pairs above the threshold."""
    total = int(det_offset[-1])
    if not config.decompose:
        return frame_of.astype(np.int64)
    rows, cols = [], []
    for f, (v, a) in enumerate(frames):
        i, j = np.nonzero(np.triu((a > config.match_threshold) & (v[:, None] != v[None, :]), 1))
        rows.append(i + det_offset[f])
        cols.append(j + det_offset[f])
    i, j = (np.concatenate(rows), np.concatenate(cols)) if rows else (np.zeros(0, int), np.zeros(0, int))
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(total, total))
    return connected_components(graph, directed=False)[1].astype(np.int64)


# ------------------------------------------------------------------------------------------------------ rounding


def round_to_clusters(relaxed: np.ndarray, view: np.ndarray, threshold: float = 0.5) -> np.ndarray:
    """Round a relaxed correspondence matrix to clusters with at most one detection per view.

    Args:
        relaxed: (N, N) relaxed correspondence matrix (symmetric, entries in [0, 1]).
        view: (N,) int view of every detection.
        threshold: pairs with a relaxed value above it are linked, in [0.5, 1).

    Returns:
        (N,) int64 cluster id (0..C-1, ordered by their first detection) or -1 (unmatched).
    """
    view = np.asarray(view).reshape(-1).astype(np.int64)
    n = len(view)
    relaxed = np.asarray(relaxed, dtype=np.float64)
    if relaxed.shape != (n, n):
        raise ValueError(f"relaxed must have shape ({n}, {n}), got {relaxed.shape}")
    if not 0.5 <= threshold < 1.0:
        raise ValueError(f"threshold must lie in [0.5, 1), got {threshold}")
    first = round_batch(np.nan_to_num(relaxed)[None], view[None], threshold)[0]
    return _number_clusters(first, np.array([0, n]), np.zeros(n, np.int64))

# ----------------------------------------------------------------------------------------------------- reference


def solve_relaxation_cvxpy(view: np.ndarray, affinity: np.ndarray, config: MatchingConfig = MatchingConfig(),
                           eps: float = 1e-7, max_iters: int = 200_000) -> np.ndarray:
    """The same relaxation solved by cvxpy with SCS, as a reference for small cases (N up to a few tens).

    Args:
        view: (N,) int view of every detection.
        affinity: (N, N) symmetric affinities in [0, 1]; NaN counts as 0.
        config: threshold and low-rank weight (the solver settings are not used).
        eps: SCS absolute and relative tolerance.
        max_iters: SCS iteration cap.

    Returns:
        (N, N) relaxed correspondence matrix (symmetrised, clipped to [0, 1]).

    Raises:
        RuntimeError: SCS found no optimal solution.
    """
    import cvxpy as cp

    view, affinity = _check_frame(view, affinity, "solve_relaxation_cvxpy")
    n = len(view)
    if n < 2:
        return np.eye(n)
    free = view[:, None] != view[None, :]
    gain = np.where(free, affinity - config.match_threshold, 0.0)
    one_hot = (view[:, None] == np.unique(view)[None, :]).astype(np.float64)
    x = cp.Variable((n, n), PSD=True)
    constraints = [cp.diag(x) == 1, x >= 0, x <= 1, x @ one_hot <= 1]
    same = ~free & ~np.eye(n, dtype=bool)
    if same.any():
        constraints.append(cp.multiply(same.astype(np.float64), x) == 0)
    problem = cp.Problem(cp.Maximize(0.5 * cp.sum(cp.multiply(gain, x)) - config.low_rank_weight * cp.trace(x)),
                         constraints)
    problem.solve(solver=cp.SCS, eps_abs=eps, eps_rel=eps, max_iters=max_iters)
    if problem.status not in ("optimal", "optimal_inaccurate") or x.value is None:
        raise RuntimeError(f"solve_relaxation_cvxpy: SCS ended with status {problem.status}")
    value = np.asarray(x.value)
    return np.clip(0.5 * (value + value.T), 0.0, 1.0)
