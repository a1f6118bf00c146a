"""Relative camera rotations from lifted 3D poses, robust to unknown identities, and their averaging.

Each lifted pose lives in its own camera's frame, relative to the hip midpoint. If detection ``i`` of view
``a`` and detection ``j`` of view ``b`` in the same frame show the same person, the rotation-only
Procrustes alignment of the two poses is the relative camera rotation ``R_ba = R_b R_a^T``. Identities are
unknown, so every pair of detections of a frame is a hypothesis: pairs of different people give rotations
scattered around the vertical axis (their relative heading), pairs of the same person agree. The consensus
is the hypothesis with the most support within an angle (a kernel vote over many frames), refined by the
chordal mean of its inliers. The inlier pairs are returned as candidate cross-view matches.

Absolute rotations follow by chordal averaging over the view graph (spectral initialisation, then iteratively
reweighted L1 refinement), camera 0 being the reference.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from humancal.calibration.types import CalibrationError, LiftedPoses
from humancal.geometry.rotations import project_to_rotmat, rotation_angle_deg, rotmat_to_quat_xyzw
from humancal.tables.detections import DenseDetections

__all__ = ["PairRotation", "pairwise_rotations", "average_rotations", "procrustes_rotations"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PairRotation:
    """The consensus rotation of one view pair and the detection pairs that support it.

    Attributes:
        view_a, view_b: the views (``view_a < view_b``).
        R_ba: (3, 3) rotation from camera ``a`` to camera ``b`` coordinates.
        rows_a, rows_b: (M,) detection rows of the supporting pairs (same frame).
        angle_deg: (M,) deviation of each supporting pair's rotation from ``R_ba``, degrees.
        pose_error_m: (M,) RMS joint distance of each supporting pair after alignment, metres.
        num_frames: frames in which both views have detections.
    """

    view_a: int
    view_b: int
    R_ba: np.ndarray
    rows_a: np.ndarray
    rows_b: np.ndarray
    angle_deg: np.ndarray
    pose_error_m: np.ndarray
    num_frames: int

    @property
    def support(self) -> int:
        """Number of frames with at least one supporting pair."""
        return 0 if len(self.rows_a) == 0 else len(np.unique(self.rows_a))


def procrustes_rotations(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted rotation-only alignment ``target ~ R @ source`` of many pose pairs (both already centred).

    Args:
        source, target: (M, J, 3) poses.
        weights: (M, J) non-negative joint weights.

    Returns:
        R: (M, 3, 3) rotations; error_m: (M,) weighted RMS distance after alignment.
    """
    M = np.einsum("mj,mjk,mjl->mkl", weights, target, source)
    R = project_to_rotmat(M)
    aligned = source @ R.transpose(0, 2, 1)
    err = np.sqrt((weights * ((aligned - target) ** 2).sum(-1)).sum(1) / np.maximum(weights.sum(1), 1e-12))
    return R, err


def _pair_hypotheses(detections, lifted, a, b, max_frames, rng):
    """All cross pairs of detections of views a, b in shared frames: rows and Procrustes rotations."""
    rows_a_all = np.flatnonzero((detections.view == a) & lifted.valid)
    rows_b_all = np.flatnonzero((detections.view == b) & lifted.valid)
    frames = np.intersect1d(detections.frame[rows_a_all], detections.frame[rows_b_all])
    n_frames = len(frames)
    if len(frames) > max_frames:
        frames = np.sort(rng.choice(frames, max_frames, replace=False))
    fa = detections.frame[rows_a_all]
    fb = detections.frame[rows_b_all]
    ra = rows_a_all[np.isin(fa, frames)]
    rb = rows_b_all[np.isin(fb, frames)]
    # Cartesian product within each frame via a merge on the frame number.
    order_a = np.argsort(detections.frame[ra], kind="stable")
    order_b = np.argsort(detections.frame[rb], kind="stable")
    ra, rb = ra[order_a], rb[order_b]
    fa, fb = detections.frame[ra], detections.frame[rb]
    start_b = np.searchsorted(fb, frames)
    count_b = np.searchsorted(fb, frames, side="right") - start_b
    idx_frame = np.searchsorted(frames, fa)
    reps = count_b[idx_frame]
    pair_a = np.repeat(ra, reps)
    offsets = np.concatenate([np.arange(c) for c in reps]) if len(reps) else np.zeros(0, int)
    pair_b = rb[np.repeat(start_b[idx_frame], reps) + offsets]
    w = np.sqrt(detections.scores[pair_a] * detections.scores[pair_b]) + 0.05
    R, err = procrustes_rotations(lifted.joints_cam_m[pair_a], lifted.joints_cam_m[pair_b], w)
    return pair_a, pair_b, R, err, n_frames


def _consensus(R: np.ndarray, weight: np.ndarray, threshold_deg: float, max_centres: int, rng) -> np.ndarray:
    """Kernel vote: the hypothesis with the largest weighted support within ``threshold_deg``, then refined."""
    q = rotmat_to_quat_xyzw(R)
    centres = np.arange(len(q)) if len(q) <= max_centres else rng.choice(len(q), max_centres, replace=False)
    half = np.radians(threshold_deg) / 2.0
    best, best_score = 0, -1.0
    for chunk in np.array_split(centres, max(1, len(centres) // 200)):
        cos_half = np.abs(q[chunk] @ q.T)  # cos of half the relative angle
        ang = np.arccos(np.clip(cos_half, -1.0, 1.0))
        score = (weight * np.clip(1.0 - (ang / half) ** 2, 0.0, None)).sum(1)
        k = int(score.argmax())
        if score[k] > best_score:
            best, best_score = chunk[k], score[k]
    centre = R[best]
    for thr in (threshold_deg, 0.7 * threshold_deg):
        inl = rotation_angle_deg(np.einsum("mji,jk->mik", R, centre)) < thr
        if inl.sum() == 0:
            break
        centre = project_to_rotmat((weight[inl, None, None] * R[inl]).sum(0))
    return centre


def pairwise_rotations(
    detections: DenseDetections,
    lifted: LiftedPoses,
    num_views: int,
    rng: np.random.Generator,
    *,
    max_frames: int = 200,
    max_pose_error_m: float = 0.15,
    threshold_deg: float = 10.0,
    max_centres: int = 600,
) -> list[PairRotation]:
    """Consensus relative rotation of every view pair that shares frames.

    Args:
        detections: dense detections of all views.
        lifted: lifted poses in camera frames, row-aligned (invalid rows are skipped).
        num_views: V.
        rng: randomness for frame and centre subsampling.
        max_frames: shared frames used per view pair (evenly at random).
        max_pose_error_m: pairs whose aligned poses differ more (RMS) cannot be the same person.
        threshold_deg: support radius of the vote and inlier threshold, degrees.
        max_centres: hypotheses tried as vote centres.

    Returns:
        One :class:`PairRotation` per view pair with at least one plausible pair (may be empty).
    """
    out = []
    for a in range(num_views):
        for b in range(a + 1, num_views):
            pa, pb, R, err, n_frames = _pair_hypotheses(detections, lifted, a, b, max_frames, rng)
            plausible = err < max_pose_error_m
            if plausible.sum() < 3:
                continue
            pa, pb, R, err = pa[plausible], pb[plausible], R[plausible], err[plausible]
            weight = 1.0 / np.maximum(err, 0.03)
            centre = _consensus(R, weight, threshold_deg, max_centres, rng)
            ang = rotation_angle_deg(np.einsum("mji,jk->mik", R, centre))
            inl = ang < threshold_deg
            out.append(PairRotation(a, b, centre, pa[inl], pb[inl], ang[inl], err[inl], n_frames))
            logger.debug("views %d-%d: %d/%d pairs support the rotation (%d frames)", a, b, inl.sum(), len(inl),
                         n_frames)
    return out


def average_rotations(
    pairs: list[PairRotation], num_views: int, *, min_support: int = 5, iterations: int = 30
) -> tuple[np.ndarray, np.ndarray]:
    """Absolute rotations ``R_cam_from_world`` (camera 0 = identity) from relative ones (chordal L1 averaging).

    Args:
        pairs: relative rotations; an edge needs ``support >= min_support`` frames.
        num_views: V.
        min_support: minimum support of a usable edge.
        iterations: IRLS iterations.

    Returns:
        R: (V, 3, 3) rotations; edge_residual_deg: (len(pairs),) disagreement of each edge with the result
        (NaN for unused edges).

    Raises:
        CalibrationError: a view is not connected to view 0 by usable edges.
    """
    edges = [(p.view_a, p.view_b, p.R_ba, float(p.support)) for p in pairs if p.support >= min_support]
    _check_connected(edges, num_views)
    V = num_views
    G = np.zeros((3 * V, 3 * V))
    for a, b, R_ba, w in edges:
        G[3 * b : 3 * b + 3, 3 * a : 3 * a + 3] += w * R_ba
        G[3 * a : 3 * a + 3, 3 * b : 3 * b + 3] += w * R_ba.T
    for v in range(V):
        G[3 * v : 3 * v + 3, 3 * v : 3 * v + 3] += np.eye(3) * sum(w for a, b, _, w in edges if v in (a, b))
    _, vecs = np.linalg.eigh(G)
    X = vecs[:, -3:].reshape(V, 3, 3)
    if np.sum(np.linalg.det(X) < 0) > V / 2:
        X[:, :, 0] *= -1
    R = project_to_rotmat(X)
    R = R @ R[0].T
    for _ in range(iterations):
        new = R.copy()
        for v in range(1, V):
            acc = np.zeros((3, 3))
            for a, b, R_ba, w in edges:
                if b == v:
                    est = R_ba @ R[a]
                elif a == v:
                    est = R_ba.T @ R[b]
                else:
                    continue
                acc += w * est / max(np.linalg.norm(est - R[v]), 1e-3)
            new[v] = project_to_rotmat(acc)
        converged = np.abs(new - R).max() < 1e-7
        R = new
        if converged:
            break
    residual = np.full(len(pairs), np.nan)
    for k, p in enumerate(pairs):
        if p.support >= min_support:
            residual[k] = rotation_angle_deg(p.R_ba.T @ R[p.view_b] @ R[p.view_a].T)
    return R, residual


def _check_connected(edges, num_views: int) -> None:
    reached = {0}
    frontier = [0]
    while frontier:
        v = frontier.pop()
        for a, b, _, _ in edges:
            for x, y in ((a, b), (b, a)):
                if x == v and y not in reached:
                    reached.add(y)
                    frontier.append(y)
    missing = sorted(set(range(num_views)) - reached)
    if missing:
        raise CalibrationError(
            f"views {missing} share no consistently matched people with view 0 (too few frames where the same "
            "person is seen together): their rotations cannot be estimated"
        )
