"""One camera placed again against the people the other cameras agree on: PnP with RANSAC, focal length unknown,
who is who unknown.

The other views' people are 3D keypoints per frame (``people[f]``: P x 23 x 3, world metres). A hypothesis is one
detection of the view matched to one person of the same frame: at each focal length of a grid over the plausible
fields of view, OpenCV's PnP (SQPnP) gives a pose from that pair's keypoints, and the hypothesis scores the number of
the view's detections that then lie within ``match_sigma`` keypoint stds of some projected person (median over
their joints). The best one is refined by least squares (focal, rotation, translation; Huber loss) on every
detection it explains, matched again to the nearest person, twice.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from humancal.camera import Camera, intrinsic_matrix
from humancal.geometry.rotations import rotmat_to_rotvec, rotvec_to_rotmat
from humancal.tables.detections import DenseDetections

__all__ = ["Reregistration", "reregister_view"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Reregistration:
    """A view placed again by :func:`reregister_view`.

    Attributes:
        camera: the new camera (pinhole, the given principal point and image size).
        explained_fraction: fraction of the view's scored detections within ``match_sigma`` of a person.
        scored: detections scored.
        median_error_px: median over the explained detections of their keypoints' median reprojection error, pixels.
    """

    camera: Camera
    explained_fraction: float
    scored: int
    median_error_px: float


def _sigma_px(keypoints_px: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        size = np.nanmax(np.linalg.norm(keypoints_px - np.nanmean(keypoints_px, -2, keepdims=True), axis=-1), -1)
    return np.maximum(0.02 * np.nan_to_num(size), 1.0)


class _Scorer:
    """The view's detections and the others' people over a set of frames, for scoring and matching cameras."""

    def __init__(self, rows, detections: DenseDetections, people: dict[int, np.ndarray], min_score, min_joints):
        self.rows = np.asarray(rows)
        conf = detections.scores[self.rows] >= min_score
        keep = conf.sum(1) >= min_joints
        self.rows, conf = self.rows[keep], conf[keep]
        self.frames = detections.frame[self.rows]
        self.kp = np.where(conf[..., None], detections.keypoints_px[self.rows], np.nan)  # (N, 23, 2)
        self.sigma = _sigma_px(self.kp)
        # per detection: its frame's people (padded to the most people of a frame, NaN rows)
        most = max((len(people[f]) for f in np.unique(self.frames)), default=0)
        self.people = np.full((len(self.rows), max(most, 1), self.kp.shape[1], 3), np.nan)
        for i, f in enumerate(self.frames):
            self.people[i, : len(people[f])] = people[f]

    def errors(self, K, R, t) -> np.ndarray:
        """(N, P) median joint error (in stds) of each detection against each projected person of its frame."""
        X = self.people @ R.T + t
        depth = X[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = X[..., :2] / depth[..., None] @ K[:2, :2].T + K[:2, 2]
        uv = np.where((depth > 1e-6)[..., None], uv, np.nan)
        distance = np.linalg.norm(uv - self.kp[:, None], axis=-1)  # (N, P, 23)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN: no shared joint, no match
            return np.nanmedian(distance, axis=-1) / self.sigma[:, None]

    def explained(self, K, R, t, match_sigma) -> tuple[int, np.ndarray]:
        """How many detections lie near a person, and the best person of each (-1: none)."""
        errors = np.nan_to_num(self.errors(K, R, t), nan=np.inf)
        best = errors.argmin(1)
        near = errors[np.arange(len(best)), best] < match_sigma
        return int(near.sum()), np.where(near, best, -1)


def _pnp(X: np.ndarray, x: np.ndarray, K: np.ndarray):
    """(R, t) from 3D-2D pairs by SQPnP, or None."""
    try:
        ok, rvec, tvec = cv2.solvePnP(X.astype(np.float64), x.astype(np.float64), K, None, flags=cv2.SOLVEPNP_SQPNP)
    except cv2.error:
        return None
    if not ok or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
        return None
    return cv2.Rodrigues(rvec)[0], tvec.reshape(3)


def _hypotheses(scorer: _Scorer, max_frames: int, rng: np.random.Generator):
    """(detection index, person index) pairs of a spread of frames, with at least 6 shared joints."""
    frames = np.unique(scorer.frames)
    if len(frames) > max_frames:
        frames = frames[np.linspace(0, len(frames) - 1, max_frames).round().astype(int)]
    out = []
    for i in np.flatnonzero(np.isin(scorer.frames, frames)):
        seen = np.isfinite(scorer.kp[i]).all(-1)
        for p in range(scorer.people.shape[1]):
            if (seen & np.isfinite(scorer.people[i, p]).all(-1)).sum() >= 6:
                out.append((i, p))
    order = rng.permutation(len(out))
    return [out[k] for k in order]


def _refine(scorer: _Scorer, match: np.ndarray, f, R, t, pp, bounds):
    """Least-squares (log focal, rotation vector, translation) on the matched detections' keypoints."""
    idx = np.flatnonzero(match >= 0)
    X = scorer.people[idx, match[idx]]  # (n, 23, 3)
    x = scorer.kp[idx]
    w = 1.0 / scorer.sigma[idx]
    ok = np.isfinite(X).all(-1) & np.isfinite(x).all(-1)
    X, x, w = X[ok], x[ok], np.broadcast_to(w[:, None], ok.shape)[ok]
    if len(X) < 6:
        return f, R, t

    def residuals(p):
        K = intrinsic_matrix(np.exp(p[0]), np.exp(p[0]), *pp)
        Xc = X @ rotvec_to_rotmat(p[1:4]).T + p[4:]
        z = np.maximum(Xc[:, 2:3], 1e-6)
        return ((Xc[:, :2] / z @ K[:2, :2].T + K[:2, 2] - x) * w[:, None]).ravel()

    start = np.r_[np.log(f), rotmat_to_rotvec(R), t]
    lo, hi = np.log(bounds)
    start[0] = np.clip(start[0], lo + 1e-9, hi - 1e-9)
    bounds_lsq = (np.r_[lo, np.full(6, -np.inf)], np.r_[hi, np.full(6, np.inf)])
    solution = least_squares(residuals, start, loss="huber", f_scale=2.5, bounds=bounds_lsq, max_nfev=200)
    p = solution.x
    return float(np.exp(p[0])), rotvec_to_rotmat(p[1:4]), p[4:]


def reregister_view(
    rows: np.ndarray,
    detections: DenseDetections,
    people: dict[int, np.ndarray],
    principal_point_px: np.ndarray,
    width_px: int,
    height_px: int,
    focal_bounds_px: tuple[float, float],
    *,
    min_score: float = 0.2,
    min_joints: int = 8,
    match_sigma: float = 5.0,
    focal_steps: int = 10,
    max_frames: int = 12,
    max_hypotheses: int = 300,
    enough: float = 0.9,
    focal_guess_px: float | None = None,
    seed: int = 0,
) -> Reregistration | None:
    """Place one view again against the other views' people (see the module docstring).

    Args:
        rows: the view's detection rows (any frames; those without people are not used).
        detections: the detections ``rows`` index.
        people: frame -> (P, 23, 3) keypoints placed by the other views, world metres (NaN where missing).
        principal_point_px: (2,) the view's principal point.
        width_px, height_px: its image size.
        focal_bounds_px: (low, high) plausible focal lengths, pixels.
        min_score, min_joints: detections need this many joints of at least this confidence to be used.
        match_sigma: a detection is explained by a person within this many keypoint stds (median over joints).
        focal_steps: focal lengths tried per hypothesis (log-spaced over the bounds).
        max_frames: hypotheses are drawn from at most this many frames (spread evenly).
        max_hypotheses: at most this many (detection, person) pairs are tried.
        enough: the search stops at a pose that explains this fraction of the scored detections.
        focal_guess_px: a focal length tried first (e.g. the other views' field of view).
        seed: the order in which hypotheses are tried.

    Returns:
        :class:`Reregistration`, or None when no hypothesis explains three detections.
    """
    rows = np.asarray(rows)
    rows = rows[np.isin(detections.frame[rows], list(people))]
    scorer = _Scorer(rows, detections, people, min_score, min_joints)
    if len(scorer.rows) < 3:
        return None
    pp = np.asarray(principal_point_px, dtype=np.float64)
    focals = np.exp(np.linspace(*np.log(focal_bounds_px), focal_steps))
    if focal_guess_px is not None and np.isfinite(focal_guess_px):
        focals = np.r_[np.clip(focal_guess_px, *focal_bounds_px), focals]
    best = (2, None)  # explain at least three detections
    target = enough * len(scorer.rows)
    for i, p in _hypotheses(scorer, max_frames, np.random.default_rng(seed))[:max_hypotheses]:
        shared = np.isfinite(scorer.kp[i]).all(-1) & np.isfinite(scorer.people[i, p]).all(-1)
        for f in focals:
            K = intrinsic_matrix(f, f, *pp)
            pose = _pnp(scorer.people[i, p][shared], scorer.kp[i][shared], K)
            if pose is None:
                continue
            count, _ = scorer.explained(K, *pose, match_sigma)
            if count > best[0]:
                best = (count, (f, *pose))
        if best[0] >= target:
            break
    if best[1] is None:
        return None
    f, R, t = best[1]
    for _ in range(3):  # refine on what it explains, match again
        _, match = scorer.explained(intrinsic_matrix(f, f, *pp), R, t, match_sigma)
        f, R, t = _refine(scorer, match, f, R, t, pp, focal_bounds_px)
    K = intrinsic_matrix(f, f, *pp)
    count, match = scorer.explained(K, R, t, match_sigma)
    errors = scorer.errors(K, R, t)
    chosen = errors[np.arange(len(match)), np.maximum(match, 0)][match >= 0] * scorer.sigma[match >= 0]
    median = float(np.median(chosen)) if len(chosen) else float("nan")
    camera = Camera(K, R, np.asarray(t, float), int(width_px), int(height_px))
    return Reregistration(camera, count / len(scorer.rows), len(scorer.rows), median)
