"""Temporal refinement of the people's skeletons once they are tracked (``docs/association.md``).

A frame-by-frame triangulation uses each frame alone: a joint seen by two views, one of them a left-right flip or
a wrong detection, has no third view to outvote it, and a joint occluded for a few frames is lost. Once the
tracks say which skeletons of consecutive frames are the same person, every joint of every person is solved again
over the whole track at once, minimising

    sum over views of  rho(reprojection error / scale_px)          (robust data term: Cauchy)
  + sum over frames of |x[t+1] - 2 x[t] + x[t-1]|^2 / acceleration^2  (smooth motion: constant-velocity prior)

with ``acceleration`` in metres per frame squared (``acceleration_mps2 / fps^2``). The data term is the
confidence-weighted DLT of :mod:`humancal.association.cluster_triangulation`, each view's rows scaled by
``focal / depth`` so that its residuals are pixels; the Cauchy loss is minimised by iteratively reweighted least
squares. Each iteration is one linear system over all joints of all people, made banded by ordering the unknowns
by (person, joint, frame, coordinate) (upper bandwidth 6): one banded Cholesky (``scipy.linalg.solveh_banded``),
linear in frames.

A joint no view could triangulate in a frame is filled from the neighbouring frames of the same track (the
smoothness term interpolates it through the rays of any single view that saw it) when the gap between the frames
it was triangulated in is at most ``max_fill_frames``; otherwise it stays missing. Interpolation only: a joint is
never extrapolated past the ends of what was seen.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solveh_banded

from humancal.association.cluster_triangulation import normal_equations, reprojection_errors_px
from humancal.config import Config, at_least, positive

__all__ = ["SmoothingConfig", "smooth_tracks"]

_BANDWIDTH = 6
"""Upper bandwidth of the system: a point's 3 coordinates (offsets 1, 2) and the same coordinate one and two
frames later (offsets 3, 6)."""
_RIDGE = 1e-6
"""Pull of every unknown towards its starting value, relative to the smoothness weight: makes the system
definite where a joint has no data at all, without moving anything measurable."""


@dataclass(frozen=True)
class SmoothingConfig(Config):
    """Settings of :func:`smooth_tracks` (defaults chosen on synthetic scenes, ``docs/association.md``).

    Attributes:
        enabled: whether :func:`humancal.association.associate` refines the tracked skeletons.
        scale_px: scale of the Cauchy loss of the reprojection errors, pixels (errors well beyond it barely count).
        acceleration_mps2: typical joint acceleration, metres per second squared (larger: follows the detections
            more closely; smaller: smoother).
        iterations: reweighting iterations (each one banded solve).
        max_fill_frames: longest gap, in frames, over which a joint missing from the triangulation is filled.
    """

    enabled: bool = True
    scale_px: float = field(default=6.0, metadata=positive())
    acceleration_mps2: float = field(default=30.0, metadata=positive())
    iterations: int = field(default=2, metadata=at_least(1, integer=True))
    max_fill_frames: int = field(default=5, metadata=at_least(0, integer=True))


def _gap_fill(order_key: np.ndarray, known: np.ndarray, values: np.ndarray, max_gap: int,
              frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of missing points between the known ones of the same sequence.

    Args:
        order_key: (N,) sequence id of every point (points sorted by sequence, then frame).
        known: (N,) whether a point is known.
        values: (N, 3) points (anything where unknown).
        max_gap: longest run of frames between two known points to interpolate across.
        frame: (N,) frame of every point.

    Returns:
        (N, 3) starting values (known ones unchanged; interpolated where fillable; the nearest known point of the
        sequence elsewhere, or 0) and (N,) whether a point is known or fillable.
    """
    n = len(known)
    idx = np.arange(n)
    prev = np.maximum.accumulate(np.where(known, idx, -1))
    nxt = np.minimum.accumulate(np.where(known, idx, n)[::-1])[::-1]
    has_prev = (prev >= 0) & (order_key[np.maximum(prev, 0)] == order_key)
    has_next = (nxt < n) & (order_key[np.minimum(nxt, n - 1)] == order_key)
    p, q = np.maximum(prev, 0), np.minimum(nxt, n - 1)
    gap = frame[q] - frame[p] - 1
    fillable = ~known & has_prev & has_next & (gap <= max_gap)
    out = np.where(known[:, None], values, 0.0)
    span = np.maximum(frame[q] - frame[p], 1)
    a = ((frame - frame[p]) / span)[:, None]
    interp = (1 - a) * values[p] + a * values[q]
    out = np.where((~known & has_prev & has_next)[:, None], interp, out)
    out = np.where((~known & has_prev & ~has_next)[:, None], values[p], out)
    out = np.where((~known & ~has_prev & has_next)[:, None], values[q], out)
    return np.nan_to_num(out), known | fillable


def smooth_tracks(frame: np.ndarray, person: np.ndarray, joints_world_m: np.ndarray, points_px: np.ndarray,
                  weights: np.ndarray, cameras: list, fps: float,
                  config: SmoothingConfig = SmoothingConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Refine the tracked skeletons over time (module docstring).

    Args:
        frame: (S,) frame of every skeleton.
        person: (S,) person of every skeleton (at most one skeleton per person and frame); -1 rows are left alone.
        joints_world_m: (S, J, 3) frame-by-frame triangulation, world metres (NaN where missing).
        points_px: (V, S, J, 2) the undistorted keypoints of the skeleton's detection in each view.
        weights: (V, S, J) their confidences, 0 where the view has no detection or the keypoint is missing.
        cameras: V pinhole cameras without distortion.
        fps: frames per second.
        config: the settings.

    Returns:
        (S, J, 3) refined joints (NaN where missing and not fillable) and (S, J) whether a joint was filled
        (missing from the triangulation, interpolated here).
    """
    S, J = joints_world_m.shape[:2]
    V = len(cameras)
    if points_px.shape != (V, S, J, 2) or weights.shape != (V, S, J):
        raise ValueError(f"smooth_tracks: points_px must be ({V}, {S}, {J}, 2) and weights ({V}, {S}, {J}), "
                         f"got {points_px.shape} and {weights.shape}")
    out = joints_world_m.copy()
    filled = np.zeros((S, J), bool)
    rows = np.flatnonzero(person >= 0)
    if len(rows) == 0:
        return out, filled
    # Unknowns ordered by (person, joint, frame): each (person, joint) is a run of consecutive entries.
    s_idx, j_idx = np.repeat(rows, J), np.tile(np.arange(J), len(rows))
    order = np.lexsort((frame[s_idx], j_idx, person[s_idx]))
    s_idx, j_idx = s_idx[order], j_idx[order]
    N = len(s_idx)
    key = person[s_idx] * J + j_idx
    f = frame[s_idx].astype(np.int64)
    x_known = joints_world_m[s_idx, j_idx]
    known = np.isfinite(x_known).all(-1)
    x0, keep = _gap_fill(key, known, x_known, config.max_fill_frames, f)

    # Smoothness triples: (n-1, n, n+1) of one (person, joint) in consecutive frames.
    mid = np.arange(1, N - 1)
    mid = mid[(key[mid - 1] == key[mid]) & (key[mid + 1] == key[mid]) & (f[mid] - f[mid - 1] == 1)
              & (f[mid + 1] - f[mid] == 1)]
    inv_acc2 = (fps * fps / config.acceleration_mps2) ** 2  # 1 / (metres per frame^2)^2
    smooth_diag = np.zeros(N)
    np.add.at(smooth_diag, mid - 1, 1.0)
    np.add.at(smooth_diag, mid, 4.0)
    np.add.at(smooth_diag, mid + 1, 1.0)
    off1 = np.zeros(N)  # coupling of n and n+1
    np.add.at(off1, mid - 1, -2.0)
    np.add.at(off1, mid, -2.0)
    off2 = np.zeros(N)  # coupling of n and n+2
    off2[mid - 1] += 1.0
    ridge = _RIDGE * inv_acc2

    pts = points_px[:, s_idx, j_idx]  # (V, N, 2)
    w = weights[:, s_idx, j_idx]  # (V, N)
    focal = np.array([0.5 * (c.K[0, 0] + c.K[1, 1]) for c in cameras])
    x = x0.copy()
    for _ in range(config.iterations):
        errors, depth = reprojection_errors_px(cameras, x, pts)
        ratio = np.nan_to_num(errors, nan=0.0, posinf=1e6) / config.scale_px
        robust = 1.0 / (1.0 + ratio * ratio)  # Cauchy IRLS weights (0 where missing or behind the camera)
        to_px = focal[:, None] / np.maximum(depth, 1e-3) / config.scale_px
        A, b = normal_equations(cameras, pts, np.where(w > 0, w * np.sqrt(robust) * to_px, 0.0))
        ab = np.zeros((_BANDWIDTH + 1, 3 * N))
        # ab[u + i - j, j] = M[i, j] for i <= j (solveh_banded's upper form); unknown 3 n + c.
        for c in range(3):
            for d in range(c, 3):
                ab[_BANDWIDTH - (d - c), 3 * np.arange(N) + d] += A[:, c, d]
        ab[_BANDWIDTH, :] += np.repeat(smooth_diag * inv_acc2 + ridge, 3)
        ab[_BANDWIDTH - 3, 3:] += np.repeat(off1[:-1] * inv_acc2, 3)
        ab[_BANDWIDTH - 6, 6:] += np.repeat(off2[:-2] * inv_acc2, 3)
        rhs = b + ridge * x0
        x = solveh_banded(ab, rhs.reshape(-1), check_finite=False).reshape(N, 3)
    x = np.where(keep[:, None], x, np.nan)
    out[s_idx, j_idx] = x
    filled[s_idx, j_idx] = keep & ~known
    return out, filled
