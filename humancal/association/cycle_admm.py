"""Batched solver and rounding behind :mod:`humancal.association.cycle_matching`.

Everything works on a batch of B problems of one size n at once: (B, n, n) matrices, (B, n) view labels.

The ADMM splits the relaxation into a positive semidefinite X and a copy Y in the polyhedron of the linear
constraints (unit diagonal, zeros between detections of one view, and, row by row and view by view, entries
``>= 0`` summing to at most 1), with the scaled dual U:

    X <- Proj_psd(sym(Y - U) + (gain / 2 - low_rank_weight * I) / rho)     (one batched eigh)
    Z <- over_relaxation * X + (1 - over_relaxation) * Y
    Y <- Proj_poly(Z + U)                                                   (closed form per row and view)
    U <- U + Z - Y

and residual balancing of rho (Boyd et al. 2011, section 3.4.1). Problems leave the batch when both the primal
residual ||X - Y|| and the dual residual rho ||Y - Y_prev|| (Frobenius, divided by n) fall below the tolerance.
"""

from __future__ import annotations

import numpy as np

__all__ = ["project_capped_simplex", "round_batch", "solve_batch"]


def _local_views(view: np.ndarray) -> tuple[np.ndarray, int, int]:
    """(B, n) views renumbered 0..V-1 within each problem; V; the most detections of one view in one problem."""
    b, n = view.shape
    order = np.argsort(view, axis=1, kind="stable")
    srt = np.take_along_axis(view, order, axis=1)
    new = np.concatenate([np.ones((b, 1), bool), srt[:, 1:] != srt[:, :-1]], axis=1)
    local = np.empty_like(order)
    np.put_along_axis(local, order, np.cumsum(new, axis=1) - 1, axis=1)
    if not local.size:
        return local, 0, 0
    num_views = int(local.max()) + 1
    per_view = int((local[:, :, None] == np.arange(num_views)).sum(axis=1).max())
    return local, num_views, per_view


class _Polyhedron:
    """Projection onto the linear constraints of (B, n, n) problems with views (B, n) and real detections (B, n).

    The free entries (between real detections of different views) of every row go, view by view, onto
    {y >= 0, sum y <= 1}; the diagonal is 1 and every other entry 0 (padding detections stay alone).

    The row-view blocks are summed with one ``bincount`` over every entry's block (problem, row, column's view):
    linear in the entries, where a product with a one-hot (n, V) matrix grows with the views too.
    """

    def __init__(self, view: np.ndarray, real: np.ndarray):
        local, num_views, per_view = _local_views(view)
        self.n = view.shape[1]
        self.free = (local[:, :, None] != local[:, None, :]) & real[:, :, None] & real[:, None, :]
        self.per_view = per_view
        self.local, self.num_views = local, num_views
        self._blocks: np.ndarray | None = None

    def subset(self, keep: np.ndarray) -> _Polyhedron:
        out = object.__new__(_Polyhedron)
        out.n, out.per_view, out.num_views = self.n, self.per_view, self.num_views
        out.free, out.local, out._blocks = self.free[keep], self.local[keep], None
        return out

    def __call__(self, z: np.ndarray) -> np.ndarray:
        if self.per_view > 1:
            y = self._cap_blocks(np.where(self.free, np.maximum(z, 0.0), 0.0))
        else:
            y = np.where(self.free, np.clip(z, 0.0, 1.0), 0.0)
        idx = np.arange(self.n)
        y[:, idx, idx] = 1.0
        return y

    def _block_of_entry(self) -> np.ndarray:
        """(B * n * n,) int64 the row-view block of every entry: (problem * n + row) * V + the column's view
        (computed once per batch of problems)."""
        if self._blocks is None:
            b, n = self.local.shape
            rows = np.arange(b * n, dtype=np.int64).reshape(b, n, 1) * self.num_views
            self._blocks = (rows + self.local[:, None, :]).reshape(-1)
        return self._blocks

    def _cap_blocks(self, y: np.ndarray) -> np.ndarray:
        """Row-view blocks of nonnegative ``y`` summing to more than 1 go onto the simplex: y - theta clipped at 0,
        theta found by Michelot's active-set iteration (exact after at most K rounds)."""
        b, n, _ = y.shape
        block = self._block_of_entry()
        size = b * n * self.num_views

        def block_sums(values: np.ndarray) -> np.ndarray:
            return np.bincount(block, weights=values.reshape(-1), minlength=size)

        over = block_sums(y) > 1.0  # (B * n * V,)
        if not over.any():
            return y
        active = y > 0.0
        theta = np.zeros_like(y)
        for _ in range(self.per_view):
            count = block_sums(active.astype(np.float64))
            total = block_sums(y * active)
            theta_block = np.where(over, (total - 1.0) / np.maximum(count, 1.0), 0.0)
            theta = theta_block[block].reshape(b, n, n)
            still = active & (y > theta)
            if (still == active).all():
                break
            active = still
        return np.maximum(y - theta, 0.0)


def project_capped_simplex(y: np.ndarray) -> np.ndarray:
    """Euclidean projection of every vector along the last axis onto {y >= 0, sum y <= 1} (a reference for tests
    of the blockwise projection).

    Args:
        y: (..., K) vectors.

    Returns:
        (..., K) projected vectors.
    """
    y = np.maximum(np.asarray(y, dtype=np.float64), 0.0)
    over = y.sum(axis=-1) > 1.0
    srt = -np.sort(-y[over], axis=-1)
    csum = np.cumsum(srt, axis=-1)
    k = np.arange(1, y.shape[-1] + 1)
    count = ((srt - (csum - 1.0) / k > 0.0) * k).max(axis=-1)
    theta = (np.take_along_axis(csum, (count - 1)[:, None], axis=-1)[:, 0] - 1.0) / count
    y[over] = np.maximum(y[over] - theta[:, None], 0.0)
    return y


def _project_psd(m: np.ndarray) -> np.ndarray:
    """(B, n, n) the nearest positive semidefinite matrices (Frobenius) to symmetric ``m``: the eigenvalues clipped
    at 0. Rebuilt from whichever side of the spectrum has fewer eigenvalues over the batch (the positive part, or
    ``m`` less its negative part): the solutions are of low rank, so this is usually a few columns."""
    w, q = np.linalg.eigh(m)
    n = m.shape[-1]
    positive = int((w > 0.0).sum(axis=1).max(initial=0))
    negative = int((w < 0.0).sum(axis=1).max(initial=0))
    if positive <= negative:
        q, w = q[:, :, n - positive:], np.maximum(w[:, n - positive:], 0.0)
        return (q * w[:, None, :]) @ q.transpose(0, 2, 1)
    q, w = q[:, :, :negative], np.minimum(w[:, :negative], 0.0)
    return m - (q * w[:, None, :]) @ q.transpose(0, 2, 1)


def solve_batch(gain: np.ndarray, view: np.ndarray, real: np.ndarray, start: np.ndarray, dual: np.ndarray, *, rho: float,
                low_rank_weight: float, over_relaxation: float, tolerance: float, max_iterations: int):
    """Solve B relaxations of one size by ADMM.

    Args:
        gain: (B, n, n) symmetric pair gains (affinity - threshold between different views, 0 elsewhere).
        view: (B, n) int views.
        real: (B, n) bool, False for padding detections (kept alone).
        start: (B, n, n) starting correspondence matrices (projected onto the linear constraints first).
        dual: (B, n, n) starting unscaled duals (zeros for a cold start).
        rho: initial penalty; low_rank_weight: nuclear-norm weight; over_relaxation: in [1, 2);
        tolerance: residual per entry; max_iterations: cap.

    Returns:
        relaxed: (B, n, n) symmetrised Y, clipped to [0, 1]; dual: (B, n, n) unscaled duals;
        iterations: (B,) int64; converged: (B,) bool.
    """
    b, n, _ = gain.shape
    project = _Polyhedron(view, real)
    linear = 0.5 * gain - low_rank_weight * np.eye(n)
    y = project(np.array(start, dtype=np.float64))
    rho_b = np.full((b, 1, 1), float(rho))
    u = dual / rho_b
    out_y, out_dual = np.empty_like(y), np.empty_like(y)
    iterations = np.zeros(b, dtype=np.int64)
    converged = np.zeros(b, bool)
    active = np.arange(b)
    for it in range(1, max_iterations + 1):
        v = y - u
        x = _project_psd(0.5 * (v + v.transpose(0, 2, 1)) + linear / rho_b)
        z = over_relaxation * x + (1.0 - over_relaxation) * y
        y_prev = y
        y = project(z + u)
        u = u + z - y
        primal = np.sqrt(((x - y) ** 2).sum(axis=(1, 2))) / n
        change = rho_b[:, 0, 0] * np.sqrt(((y - y_prev) ** 2).sum(axis=(1, 2))) / n
        ok = (primal < tolerance) & (change < tolerance)
        done = ok if it < max_iterations else np.ones_like(ok)
        if done.any():
            ids = active[done]
            out_y[ids], out_dual[ids] = y[done], u[done] * rho_b[done]
            iterations[ids], converged[ids] = it, ok[done]
            keep = ~done
            if not keep.any():
                break
            active, y, u, rho_b, linear = active[keep], y[keep], u[keep], rho_b[keep], linear[keep]
            primal, change, project = primal[keep], change[keep], project.subset(keep)
        # Residual balancing: keep the two residuals within a factor 10 of each other.
        factor = np.where(primal > 10.0 * change, 2.0, np.where(change > 10.0 * primal, 0.5, 1.0))[:, None, None]
        rho_b, u = rho_b * factor, u / factor
    relaxed = np.clip(0.5 * (out_y + out_y.transpose(0, 2, 1)), 0.0, 1.0)
    return relaxed, out_dual, iterations, converged


def round_batch(relaxed: np.ndarray, view: np.ndarray, threshold: float) -> np.ndarray:
    """Round B relaxed matrices to clusters with at most one detection per view.

    Pairs above ``threshold`` are linked; a linked group is a cluster when its views are distinct and every member's
    mean relaxed value to the others exceeds the threshold. Other groups are split greedily (:func:`_split`).

    Args:
        relaxed: (B, n, n) symmetric relaxed matrices.
        view: (B, n) int views.
        threshold: link threshold, >= 0.5.

    Returns:
        (B, n) int64: for every detection the index of the first detection of its cluster, or -1 (unmatched).
    """
    b, n, _ = relaxed.shape
    if n == 0 or b == 0:
        return np.full((b, n), -1, dtype=np.int64)
    same_view = view[:, :, None] == view[:, None, :]
    link = (relaxed > threshold) & ~same_view
    reach = (link | np.eye(n, dtype=bool)).astype(np.float32)
    for _ in range(int(np.ceil(np.log2(max(n, 2))))):
        reach = np.minimum(reach @ reach, 1.0)
    reach = reach > 0.5
    size = reach.sum(axis=2)
    first = np.argmax(reach, axis=2)
    conflict = (reach & same_view).sum(axis=2) > 1
    mean_link = ((relaxed * reach).sum(axis=2) - 1.0) / np.maximum(size - 1, 1)
    bad_row = conflict | ((size >= 2) & (mean_link <= threshold))
    bad = (reach & bad_row[:, None, :]).any(axis=2)
    out = np.where((size >= 2) & ~bad, first, -1)
    for p in np.flatnonzero(bad.any(axis=1)):
        for members in {tuple(np.flatnonzero(reach[p, i])) for i in np.flatnonzero(bad[p])}:
            for group in _split(np.array(members), view[p], relaxed[p], threshold):
                out[p, group] = group.min()
    return out


def _split(members: np.ndarray, view: np.ndarray, x: np.ndarray, threshold: float) -> list[np.ndarray]:
    """Greedy clusters inside an inconsistent linked group, the candidate with the most views first.

    Every remaining detection seeds a candidate: itself, then its partners by decreasing relaxed value, each taken
    when its view is new to the candidate, its value to the seed exceeds the threshold and its mean value to the
    candidate's members too. The candidate with the most detections (then the largest relaxed sum) is kept, its
    detections removed, and so on while a candidate of two or more remains.
    """
    remaining = np.sort(members)
    groups = []
    while len(remaining) >= 2:
        sub = x[np.ix_(remaining, remaining)]
        vr = view[remaining]
        best, best_score = [], None
        for seed in range(len(remaining)):
            cand = [seed]
            for j in np.argsort(-sub[seed], kind="stable").tolist():
                if j != seed and sub[seed, j] > threshold and vr[j] not in vr[cand] and sub[j, cand].mean() > threshold:
                    cand.append(j)
            score = (len(cand), float(sub[np.ix_(cand, cand)].sum()))
            if best_score is None or score > best_score:
                best, best_score = cand, score
        if len(best) < 2:
            break
        groups.append(remaining[best])
        remaining = np.delete(remaining, best)
    return groups
