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
feasible X is feasible); parts of all frames are solved together, padded to a few sizes
(:mod:`humancal.association.cycle_batching`). Two kinds of part need no solver: one detection per view and no pair
below the threshold (the optimum is all ones), and no pair above it (the identity). The settings are a
:class:`~humancal.association.matching_config.MatchingConfig`.

Rounding links the pairs with X_ab > 0.5 (at most one per view and row, by the row sums). A linked group is a
cluster when its views are distinct and every member's mean relaxed value to the others exceeds 0.5; any other
group is split greedily, the candidate cluster with the most corresponding views first. Detections left alone are
unmatched (-1): false positives or people seen by one view only. :func:`solve_relaxation_cvxpy` solves the same
program with cvxpy (SCS) as a reference on small cases.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from humancal.association.cycle_admm import round_batch
from humancal.association.cycle_batching import (
    FlatFrames,
    SolvedFrames,
    flat_starts,
    independent_parts,
    number_clusters,
    solve_parts,
)
from humancal.association.matching_config import MatchingConfig

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


def _objective(view: np.ndarray, affinity: np.ndarray, relaxed: np.ndarray, config: MatchingConfig) -> float:
    """The relaxation's objective at ``relaxed`` for validated (N,) views and (N, N) affinities."""
    free = view[:, None] != view[None, :]
    gain = np.where(free, affinity - config.match_threshold, 0.0)
    return float(0.5 * (gain * relaxed).sum() - config.low_rank_weight * np.trace(relaxed))


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
    return _objective(view, affinity, np.asarray(relaxed, dtype=np.float64), config)


# ------------------------------------------------------------------------------------------------- frames, parts


def match_frames(views: Sequence[np.ndarray], affinities: Sequence[np.ndarray],
                 config: MatchingConfig = MatchingConfig(),
                 warm_starts: Sequence[WarmStart | None] | None = None) -> list[FrameMatching]:
    """Match the detections of many frames; the problems of all frames are solved together in batches.

    The frames are laid out flat, split into independent problems (the connected parts of the pairs above the
    threshold, or whole frames), solved and rounded in batches of padded problems, and numbered back per frame.

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
    flat = _lay_out(views, affinities, warm_starts)
    start, dual = flat_starts(warm_starts, flat)
    labels = independent_parts(flat, config.match_threshold, config.decompose)
    solved = solve_parts(flat, labels, start, dual, config)
    if not solved.converged.all():
        logger.debug("cycle matching: %d of %d frames hit the iteration cap (%d)", int((~solved.converged).sum()),
                     len(flat.frames), config.max_iterations)
    return _frame_matchings(flat, solved, config)


def _lay_out(views: Sequence[np.ndarray], affinities: Sequence[np.ndarray],
             warm_starts: Sequence[WarmStart | None] | None) -> FlatFrames:
    """The validated frames, laid out flat.

    Raises:
        ValueError: mismatched numbers of frames, or a frame's views or affinities invalid (see :func:`_check_frame`).
    """
    if len(views) != len(affinities):
        raise ValueError(f"views and affinities must have one entry per frame, got {len(views)} and {len(affinities)}")
    if warm_starts is not None and len(warm_starts) != len(views):
        raise ValueError(f"warm_starts must have one entry per frame ({len(views)}), got {len(warm_starts)}")
    return FlatFrames.of([_check_frame(v, a, f"frame {i}") for i, (v, a) in enumerate(zip(views, affinities))])


def _frame_matchings(flat: FlatFrames, solved: SolvedFrames, config: MatchingConfig) -> list[FrameMatching]:
    """One :class:`FrameMatching` per frame: its clusters numbered within the frame, its relaxed matrix and dual,
    the objective there, and the solver's effort."""
    cluster = number_clusters(solved.first, flat.det_offset, flat.frame_of)
    out = []
    for f, (v, a) in enumerate(flat.frames):
        x = flat.matrix(solved.relaxed, f)
        out.append(FrameMatching(cluster[flat.det_offset[f]:flat.det_offset[f + 1]], x,
                                 flat.matrix(solved.dual, f), _objective(v, a, x, config),
                                 int(solved.iterations[f]), bool(solved.converged[f])))
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
    return number_clusters(first, np.array([0, n]), np.zeros(n, np.int64))

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
