"""The batched solve behind :func:`humancal.association.cycle_matching.match_frames`: the matching problems of
many frames laid out flat, split, grouped in padded batches, solved and rounded together.

Every frame's (N_f, N_f) matrices lie flat, one frame after another (:class:`FlatFrames`); the detections of all
frames are numbered globally (rows 0..total-1, frame by frame). Each frame splits into independent problems
(:func:`independent_parts`); the problems are grouped by size, padded up to a few sizes
(:func:`padded_buckets`), so that a few batched calls of :mod:`humancal.association.cycle_admm` solve and round
them all (:func:`solve_parts`); the rounded clusters are numbered back within each frame
(:func:`number_clusters`).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import threadpoolctl
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from humancal.association.cycle_admm import round_batch, solve_batch
from humancal.association.matching_config import MatchingConfig

__all__ = ["FlatFrames", "SolvedFrames", "flat_starts", "independent_parts", "number_clusters", "padded_buckets",
           "solve_parts"]


@dataclass(frozen=True)
class FlatFrames:
    """The detections and (N_f, N_f) matrices of F frames, laid out flat one frame after another.

    Attributes:
        frames: per frame, the (N_f,) int64 views and the (N_f, N_f) float64 affinities (validated).
        size: (F,) int64 detections N_f of every frame.
        det_offset: (F + 1,) int64 global row of every frame's first detection, then the total.
        mat_offset: (F + 1,) int64 flat index of every frame's (N_f, N_f) matrix, then the sum of N_f^2.
        frame_of: (total,) frame of every detection.
        local: (total,) row of every detection within its frame.
        view: (total,) int64 view of every detection.
        affinity: (sum of N_f^2,) float64 affinities of all frames, flat.
    """

    frames: list[tuple[np.ndarray, np.ndarray]]
    size: np.ndarray
    det_offset: np.ndarray
    mat_offset: np.ndarray
    frame_of: np.ndarray
    local: np.ndarray
    view: np.ndarray
    affinity: np.ndarray

    @classmethod
    def of(cls, frames: list[tuple[np.ndarray, np.ndarray]]) -> FlatFrames:
        """The layout of frames given as validated ((N_f,) int64 views, (N_f, N_f) float64 affinities)."""
        size = np.array([len(v) for v, _ in frames], dtype=np.int64)
        det_offset = np.concatenate([[0], np.cumsum(size)]).astype(np.int64)
        mat_offset = np.concatenate([[0], np.cumsum(size**2)]).astype(np.int64)
        total = int(det_offset[-1])
        frame_of = np.repeat(np.arange(len(frames)), size)
        local = np.arange(total) - det_offset[frame_of]
        view = np.concatenate([v for v, _ in frames]) if total else np.zeros(0, np.int64)
        affinity = np.concatenate([a.reshape(-1) for _, a in frames]) if total else np.zeros(0)
        return cls(frames, size, det_offset, mat_offset, frame_of, local, view, affinity)

    @property
    def total(self) -> int:
        """The number of detections of all frames."""
        return int(self.det_offset[-1])

    def entries(self, rows: np.ndarray) -> np.ndarray:
        """(P, n, n) flat indices of the matrix entries between the detections of P problems, each given by the
        (P, n) global rows of its detections (all of one frame)."""
        frame = self.frame_of[rows[:, 0]]
        offset, size, local = self.mat_offset[frame], self.size[frame], self.local[rows]
        return offset[:, None, None] + local[:, :, None] * size[:, None, None] + local[:, None, :]

    def matrix(self, flat: np.ndarray, f: int) -> np.ndarray:
        """Frame ``f``'s (N_f, N_f) matrix of a flat array (a view of it)."""
        n = int(self.size[f])
        return flat[self.mat_offset[f]:self.mat_offset[f + 1]].reshape(n, n)

    def identity(self) -> np.ndarray:
        """The (N_f, N_f) identities of all frames, flat."""
        flat = np.zeros(int(self.mat_offset[-1]))
        for f, n in enumerate(self.size.tolist()):
            flat[self.mat_offset[f]:self.mat_offset[f + 1]:n + 1] = 1.0
        return flat


def flat_starts(warm_starts: Sequence | None, flat: FlatFrames) -> tuple[np.ndarray, np.ndarray]:
    """Starting relaxed matrices and duals of all frames, flat (identity and zeros where a frame has none).

    Args:
        warm_starts: per frame a :class:`~humancal.association.cycle_matching.WarmStart` or None; or None.
        flat: the frames' layout.

    Raises:
        ValueError: a warm start's matrices are not (N_f, N_f).
    """
    start = flat.identity()
    dual = np.zeros_like(start)
    for f, warm in enumerate(warm_starts or ()):
        if warm is None:
            continue
        n = int(flat.size[f])
        for name, m in (("relaxed", warm.relaxed), ("dual", warm.dual)):
            if m is not None and np.shape(m) != (n, n):
                raise ValueError(f"frame {f}: warm_start.{name} must have shape ({n}, {n}), got {np.shape(m)}")
        block = slice(flat.mat_offset[f], flat.mat_offset[f + 1])
        start[block] = np.nan_to_num(np.asarray(warm.relaxed, np.float64)).reshape(-1)
        if warm.dual is not None:
            dual[block] = np.nan_to_num(np.asarray(warm.dual, np.float64)).reshape(-1)
    return start, dual


def independent_parts(flat: FlatFrames, match_threshold: float, decompose: bool) -> np.ndarray:
    """(total,) int64 label of the independent problem of every detection: its frame, or (``decompose``) the
    connected part of the pairs of its frame above ``match_threshold`` (from different views)."""
    if not flat.total:
        return np.zeros(0, np.int64)
    if not decompose:
        return flat.frame_of.astype(np.int64)
    rows, cols = [], []
    for f, (v, a) in enumerate(flat.frames):
        i, j = np.nonzero(np.triu((a > match_threshold) & (v[:, None] != v[None, :]), 1))
        rows.append(i + flat.det_offset[f])
        cols.append(j + flat.det_offset[f])
    i, j = (np.concatenate(rows), np.concatenate(cols)) if rows else (np.zeros(0, int), np.zeros(0, int))
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(flat.total, flat.total))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def padded_buckets(labels: np.ndarray, view: np.ndarray) -> list[np.ndarray]:
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


@dataclass(frozen=True)
class _Bucket:
    """P problems of one padded size m, gathered from the flat frames.

    Attributes:
        members: (P, m) global rows of every problem's detections (increasing; -1: padding).
        real: (P, m) whether a slot holds a detection.
        frame: (P,) frame of every problem.
        index: (P, m, m) flat indices of the problems' matrix entries (padding reads the first detection's).
        pair: (P, m, m) whether both slots hold detections.
        view: (P, m) views; padding slots have views of their own, above every real view.
        free: (P, m, m) pairs of detections of different views.
        gain: (P, m, m) affinity minus the match threshold of the free pairs, 0 elsewhere.
    """

    members: np.ndarray
    real: np.ndarray
    frame: np.ndarray
    index: np.ndarray
    pair: np.ndarray
    view: np.ndarray
    free: np.ndarray
    gain: np.ndarray

    @classmethod
    def gather(cls, members: np.ndarray, flat: FlatFrames, match_threshold: float) -> _Bucket:
        """The bucket of problems with (P, m) global rows ``members`` (-1: padding)."""
        real = members >= 0
        rows = np.where(real, members, members[:, :1])
        index = flat.entries(rows)
        pair = real[:, :, None] & real[:, None, :]
        view = np.where(real, flat.view[rows], flat.view.max() + 1 + np.arange(members.shape[1]))
        free = pair & (view[:, :, None] != view[:, None, :])
        gain = np.where(free, flat.affinity[index] - match_threshold, 0.0)
        return cls(members, real, flat.frame_of[rows[:, 0]], index, pair, view, free, gain)


@dataclass(frozen=True)
class SolvedFrames:
    """The relaxed solutions of all frames, flat, and their rounding.

    Attributes:
        relaxed: (sum of N_f^2,) relaxed correspondence matrices (the identity where nothing was solved).
        dual: (sum of N_f^2,) ADMM duals at the end (zero where nothing was solved).
        first: (total,) global row of the first detection of every detection's cluster, or -1 (unmatched).
        iterations: (F,) ADMM iterations of the slowest problem of every frame.
        converged: (F,) whether every problem of a frame met the tolerance.
    """

    relaxed: np.ndarray
    dual: np.ndarray
    first: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray


def solve_parts(flat: FlatFrames, labels: np.ndarray, start: np.ndarray, dual: np.ndarray,
                config: MatchingConfig) -> SolvedFrames:
    """Solve and round the independent problems of all frames, bucket by bucket.

    Args:
        flat: the frames' layout.
        labels: (total,) independent problem of every detection (:func:`independent_parts`).
        start, dual: (sum of N_f^2,) starting relaxed matrices and duals, flat (:func:`flat_starts`).
        config: relaxation, solver and rounding settings.
    """
    relaxed, dual_out = flat.identity(), np.zeros_like(dual)
    first = np.full(flat.total, -1, dtype=np.int64)
    iterations = np.zeros(len(flat.frames), np.int64)
    converged = np.ones(len(flat.frames), bool)
    with _blas_controller().limit(limits=1, user_api="blas"):
        # Many small matrices: one BLAS thread is fastest, and threads fight over busy cores.
        for members in _chunks(padded_buckets(labels, flat.view)):
            bucket = _Bucket.gather(members, flat, config.match_threshold)
            x, d, its, ok = _solve_bucket(bucket, start, dual, config)
            np.maximum.at(iterations, bucket.frame, its)
            np.logical_and.at(converged, bucket.frame, ok)
            relaxed[bucket.index[bucket.pair]], dual_out[bucket.index[bucket.pair]] = x[bucket.pair], d[bucket.pair]
            rep = round_batch(x, bucket.view, config.rounding_threshold)
            took = bucket.real & (rep >= 0)
            first[members[took]] = np.take_along_axis(members, np.maximum(rep, 0), axis=1)[took]
    return SolvedFrames(relaxed, dual_out, first, iterations, converged)


MAX_BATCH_ENTRIES = 1 << 21
"""Matrix entries (problems x m x m) solved in one batch. The solver keeps a few dozen arrays of that size (16 MB
each in float64), so its memory stays bounded whatever the number of frames; the problems are independent (each
has its own penalty and stops on its own), so solving them in chunks gives the same solutions."""


def _chunks(buckets: list[np.ndarray]) -> list[np.ndarray]:
    """Each bucket's (P, m) rows cut into chunks of at most :data:`MAX_BATCH_ENTRIES` / m^2 problems."""
    out = []
    for members in buckets:
        step = max(1, MAX_BATCH_ENTRIES // members.shape[1] ** 2)
        out += [members[start:start + step] for start in range(0, len(members), step)]
    return out


def _solve_bucket(bucket: _Bucket, start: np.ndarray, dual: np.ndarray, config: MatchingConfig
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The relaxed solutions of a bucket's problems: (P, m, m) matrices and duals, (P,) iterations and (P,)
    convergence; ADMM only for the problems that need it.

    Two kinds are exact without solving: one detection per view and no losing pair (everyone matched: all ones),
    and no gaining pair (no one matched: the identity).
    """
    pair, free, gain = bucket.pair, bucket.free, bucket.gain
    shared = (pair & ~free).sum(axis=(1, 2)) > bucket.real.sum(axis=1)
    clique = ~shared & ((gain >= 0.0) | ~free).all(axis=(1, 2))
    alone = ((gain <= 0.0) | ~free).all(axis=(1, 2))
    m = bucket.members.shape[1]
    x = np.where(clique[:, None, None], pair, np.eye(m, dtype=bool)).astype(np.float64)
    d = np.zeros_like(x)
    iterations = np.zeros(len(x), np.int64)
    converged = np.ones(len(x), bool)
    hard = ~clique & ~alone
    if hard.any():
        index = bucket.index[hard]
        x[hard], d[hard], iterations[hard], converged[hard] = solve_batch(
            gain[hard], bucket.view[hard], bucket.real[hard], start[index] * pair[hard], dual[index] * pair[hard],
            rho=config.rho, low_rank_weight=config.low_rank_weight, over_relaxation=config.over_relaxation,
            tolerance=config.tolerance, max_iterations=config.max_iterations)
    return x, d, iterations, converged


def number_clusters(first: np.ndarray, det_offset: np.ndarray, frame_of: np.ndarray) -> np.ndarray:
    """(total,) cluster ids 0..C-1 within each frame, ordered by their first detection; -1 stays -1.

    Args:
        first: (total,) global row of the first detection of every detection's cluster, or -1 (unmatched).
        det_offset: (F + 1,) global row of every frame's first detection, then the total.
        frame_of: (total,) frame of every detection.
    """
    is_first = first == np.arange(len(first))
    rank = np.cumsum(is_first) - 1
    rank = rank - (rank[det_offset[frame_of]] - is_first[det_offset[frame_of]] + 1)
    return np.where(first >= 0, rank[np.maximum(first, 0)], -1).astype(np.int64)


@functools.cache
def _blas_controller() -> threadpoolctl.ThreadpoolController:
    """The BLAS libraries, inspected once (a fresh ``threadpool_limits`` costs ~0.4 ms per call)."""
    return threadpoolctl.ThreadpoolController()
