"""Initial intrinsics of every view from upright standing people (the paper's III-B, "initial intrinsics").

Per view: detections whose lifted pose is upright (``upright_score`` above a threshold) give "plumb lines"
(the paper: head to ankle midpoint; here by default shoulder midpoint to ankle midpoint, see below); their
vertical vanishing point comes from RANSAC + least squares (:mod:`.vanishing`); the focal length then follows
from the lines' heights in the lifted 3D poses and the ground plane through the ankle centres (:mod:`.focal`).
The principal point is the image centre unless given. Several frames of the same people are used, so one or
two people suffice.

Plumb line: a segment is only useful if it is vertical when the person stands. Measured on the synthetic
people (standing frames, world ground truth), the face-joint head point sits 10 cm in front of the ankle
midpoint (a 4 degree forward lean, which tilts the vanishing point whenever people face the camera), the
shoulder midpoint 2.4 cm (1.7 degrees median lean). ``plumb_top="head"`` gives the paper's line.

A view whose focal length is poorly observable from its own people (a nearly level camera: vanishing point
near infinity; a camera looking straight down: vanishing point at the image centre, where heights only give
the camera height) is *flagged* (``ill_conditioned``) with its relative uncertainty; the extrinsics stage then
recovers its focal length from the other views (:mod:`.bundle`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from humancal.calibration.focal import solve_focal
from humancal.calibration.types import (
    FOOT_JOINTS,
    PLUMB_BOTTOMS,
    PLUMB_TOPS,
    CalibrationError,
    LiftedPoses,
    ankle_midpoints,
    check_lifted,
    plumb_points,
)
from humancal.calibration.vanishing import VanishingPoint, fit_vertical_vanishing_point
from humancal.camera import intrinsic_matrix
from humancal.config import Config, at_least, in_range, positive
from humancal.tables.detections import DenseDetections

__all__ = ["IntrinsicsConfig", "IntrinsicsEstimate", "estimate_intrinsics", "upright_candidates"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class IntrinsicsConfig(Config):
    """Settings of :func:`estimate_intrinsics`.

    Attributes:
        upright_threshold: minimum ``upright_score`` of a candidate.
        plumb_top, plumb_bottom: the joints whose midpoints end the plumb line (``"head"``: mean of the face
            joints, ``"ears"``, ``"shoulders"``; ``"ankles"``, ``"feet"``: ankles, heels and toes).
        min_joint_score: minimum 2D confidence of the plumb-line joints used.
        min_line_length_px: shortest plumb line used, pixels.
        angle_threshold_deg: RANSAC angle test ``gamma``, degrees.
        ransac_iterations: two-line samples of the RANSAC.
        max_candidates: candidates per view are subsampled (evenly over time) to at most this many.
        square_pixels: one focal (fx = fy) when True, fx and fy when False.
        focal_range_rel: search range of the focal length, as multiples of the image diagonal.
        max_focal_rel_uncertainty: a view whose focal relative uncertainty exceeds this is ``ill_conditioned``.
        lean_std_deg: std of the lean of upright people's plumb lines from the true vertical, degrees (it weights
            the residuals across the lines and sets the uncertainty).
        height_rel_std: relative std of the plumb-line heights from the lifted poses.
        min_inliers: fewer vanishing-point inliers than this means "no upright person" in the view.
        missing_upright: ``"raise"`` a :class:`CalibrationError` for a view without (enough) upright people,
            or ``"defer"`` it: return an estimate with ``status="no_upright"`` and no focal, to be recovered
            from the other views by :func:`~humancal.calibration.extrinsics.estimate_extrinsics`.
        seed: RANSAC seed.
    """

    upright_threshold: float = field(default=0.5, metadata=in_range(0, 1))
    plumb_top: str = "shoulders"
    plumb_bottom: str = "ankles"
    min_joint_score: float = field(default=0.3, metadata=in_range(0, 1))
    min_line_length_px: float = field(default=30.0, metadata=at_least(0))
    angle_threshold_deg: float = field(default=2.0, metadata=in_range(0, 45, low_open=True, high_open=True))
    ransac_iterations: int = field(default=1000, metadata=positive(integer=True))
    max_candidates: int = field(default=1500, metadata=positive(integer=True))
    square_pixels: bool = True
    focal_range_rel: tuple[float, float] = (0.15, 5.0)
    max_focal_rel_uncertainty: float = field(default=0.05, metadata=positive())
    lean_std_deg: float = field(default=2.5, metadata=positive())
    height_rel_std: float = field(default=0.03, metadata=positive())
    min_inliers: int = field(default=6, metadata=at_least(3, integer=True))
    missing_upright: Literal["raise", "defer"] = "raise"
    seed: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        lo, hi = self.focal_range_rel
        if not 0.0 < lo < hi:
            raise ValueError(f"IntrinsicsConfig.focal_range_rel={self.focal_range_rel} must be 0 < low < high")
        if self.missing_upright not in ("raise", "defer"):
            raise ValueError(f"IntrinsicsConfig.missing_upright={self.missing_upright!r}; allowed: 'raise', 'defer'")
        if self.plumb_top not in PLUMB_TOPS or self.plumb_bottom not in PLUMB_BOTTOMS:
            raise ValueError(
                f"IntrinsicsConfig plumb line {self.plumb_top!r}/{self.plumb_bottom!r}: top must be one of "
                f"{list(PLUMB_TOPS)}, bottom one of {list(PLUMB_BOTTOMS)}"
            )


@dataclass(frozen=True)
class IntrinsicsEstimate:
    """The initial intrinsics of one view, with diagnostics.

    Attributes:
        view: the view index.
        K: (3, 3) intrinsic matrix, pixels (NaN focal when ``status == "no_upright"``).
        width_px, height_px: image size, pixels.
        status: ``"ok"``, ``"ill_conditioned"`` (focal poorly observable from this view alone: use the
            multi-view recovery) or ``"no_upright"`` (deferred: no focal at all).
        focal_rel_uncertainty: relative uncertainty of the focal (``inf`` when unknown).
        num_candidates: upright candidates considered.
        num_inliers: candidates agreeing with the vanishing point and the height model.
        vanishing_point_px: (2,) vertical vanishing point, pixels (may be very large or infinite).
        up_cam: (3,) world up direction in the camera frame (NaN when unknown).
        tilt_deg: angle of the optical axis below the horizontal, degrees (90 = looking straight down).
        roll_deg: rotation of the image about the optical axis (the up direction's angle from image -y), degrees.
        camera_height_m: camera height above the floor, metres (ankle plane + the ankles' height over the soles).
        vp_rms_px: RMS residual of the lines at the vanishing point, pixels.
        rms_px: RMS reprojection residual of the plumb-line tops in the focal fit, pixels.
    """

    view: int
    K: np.ndarray
    width_px: int
    height_px: int
    status: str
    focal_rel_uncertainty: float
    num_candidates: int
    num_inliers: int
    vanishing_point_px: np.ndarray
    up_cam: np.ndarray
    tilt_deg: float
    roll_deg: float
    camera_height_m: float
    vp_rms_px: float
    rms_px: float

    @property
    def ill_conditioned(self) -> bool:
        """Whether the focal of this view should come from the other views."""
        return self.status != "ok"

    @property
    def fx_px(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy_px(self) -> float:
        return float(self.K[1, 1])


def upright_candidates(
    detections: DenseDetections, lifted: LiftedPoses, rows: np.ndarray, config: IntrinsicsConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Upright candidates among ``rows``: their plumb-line tops and bottoms and the lines' 3D lengths.

    A candidate needs an upright score at least ``config.upright_threshold``, both ends detected with
    ``min_joint_score``, an image length of at least ``min_line_length_px``, and a 3D length between 0.6 and 1
    times its ``height_m`` (else the lift is broken).

    Returns:
        keep: (K,) the selected rows (indices into the detections).
        head_px, ankle_px: (K, 2) top and bottom points, pixels.
        height_m: (K,) length of the line in the lifted pose (top above bottom), metres.
    """
    valid = detections.scores[rows] >= config.min_joint_score
    head, ankle = plumb_points(detections.keypoints_px[rows], valid, config.plumb_top, config.plumb_bottom)
    top3, bottom3 = plumb_points(lifted.joints_cam_m[rows], valid, config.plumb_top, config.plumb_bottom)
    h = np.linalg.norm(top3 - bottom3, axis=1)
    ratio = h / lifted.height_m[rows]
    ok = (
        lifted.valid[rows]
        & (lifted.upright_score[rows] >= config.upright_threshold)
        & np.isfinite(head).all(1)
        & np.isfinite(ankle).all(1)
        & (np.linalg.norm(head - ankle, axis=1) >= config.min_line_length_px)
        & (ratio > 0.6)  # plumb lines span 0.75-0.9 of the height; else a broken lift
        & (ratio < 1.0)
    )
    return rows[ok], head[ok], ankle[ok], h[ok]


def _ankle_over_soles_m(joints_cam_m: np.ndarray, up_cam: np.ndarray) -> float:
    """Median height of the ankle midpoint over the lowest sole point, along the up direction, metres."""
    ankle = ankle_midpoints(joints_cam_m) @ up_cam
    soles = joints_cam_m[:, FOOT_JOINTS] @ up_cam
    return float(np.median(ankle - soles.min(1)))


def _deferred(view: int, size: tuple[int, int], pp: np.ndarray, n: int, inliers: int) -> IntrinsicsEstimate:
    K = intrinsic_matrix(np.nan, np.nan, pp[0], pp[1])
    nan3 = np.full(3, np.nan)
    return IntrinsicsEstimate(view, K, size[0], size[1], "no_upright", np.inf, n, inliers, np.full(2, np.nan), nan3,
                              np.nan, np.nan, np.nan, np.nan, np.nan)


def _estimate_view(
    view: int,
    detections: DenseDetections,
    lifted: LiftedPoses,
    size: tuple[int, int],
    pp: np.ndarray,
    config: IntrinsicsConfig,
    rng: np.random.Generator,
) -> IntrinsicsEstimate:
    rows = np.flatnonzero(detections.view == view)
    if len(rows) == 0:
        raise CalibrationError(f"view {view} has no detections: its camera cannot be calibrated")
    keep, head, ankle, h = upright_candidates(detections, lifted, rows, config)
    if len(keep) > config.max_candidates:
        pick = np.linspace(0, len(keep) - 1, config.max_candidates).round().astype(int)
        keep, head, ankle, h = keep[pick], head[pick], ankle[pick], h[pick]
    n = len(keep)

    def fail(reason: str, inliers: int = 0) -> IntrinsicsEstimate:
        if config.missing_upright == "raise":
            raise CalibrationError(
                f"view {view}: {reason}; its focal length cannot be estimated from upright people "
                f"(IntrinsicsConfig(missing_upright='defer') recovers it from the other views)"
            )
        logger.warning("view %d: %s: its focal length will come from the other views", view, reason)
        return _deferred(view, size, pp, n, inliers)

    if n < config.min_inliers:
        return fail(f"only {n} upright detections (need {config.min_inliers})")
    scale = 0.5 * float(np.hypot(*size))
    vp = fit_vertical_vanishing_point(
        head, ankle, pp, scale, rng, angle_threshold_deg=config.angle_threshold_deg,
        iterations=config.ransac_iterations,
    )
    if vp.inliers.sum() < config.min_inliers:
        return fail(f"only {int(vp.inliers.sum())} of {n} upright detections agree on a vanishing point",
                    int(vp.inliers.sum()))
    sel = vp.inliers
    diag = float(np.hypot(*size))
    sol = solve_focal(
        vp.point_centered_h, head[sel] - pp, ankle[sel] - pp, h[sel], detections.frame[keep[sel]],
        focal_range_px=(config.focal_range_rel[0] * diag, config.focal_range_rel[1] * diag),
        square_pixels=config.square_pixels,
        lean_std_deg=config.lean_std_deg,
        height_rel_std=config.height_rel_std,
    )
    used = lifted.subset(keep[sel][sol.inliers])
    K = intrinsic_matrix(sol.fx_px, sol.fy_px, pp[0], pp[1])
    used = used.in_camera_frame(np.broadcast_to(K, (len(used), 3, 3)))  # lengths are frame-free; the soles are not
    return _assemble(view, size, pp, n, vp, sol, used.joints_cam_m, config)


def _assemble(view, size, pp, n, vp: VanishingPoint, sol, joints_cam_m, config) -> IntrinsicsEstimate:
    K = intrinsic_matrix(sol.fx_px, sol.fy_px, pp[0], pp[1])
    up = sol.up_cam
    tilt = float(np.degrees(np.arcsin(np.clip(-up[2], -1, 1))))
    roll = float(np.degrees(np.arctan2(up[0], -up[1])))
    ill = not (sol.focal_rel_uncertainty <= config.max_focal_rel_uncertainty)
    vp_px = pp + np.array([sol.fx_px * up[0], sol.fy_px * up[1]]) / up[2] if abs(up[2]) > 1e-12 else vp.point_px
    estimate = IntrinsicsEstimate(
        view=view,
        K=K,
        width_px=int(size[0]),
        height_px=int(size[1]),
        status="ill_conditioned" if ill else "ok",
        focal_rel_uncertainty=sol.focal_rel_uncertainty,
        num_candidates=n,
        num_inliers=int(sol.inliers.sum()),
        vanishing_point_px=np.asarray(vp_px, dtype=np.float64),
        up_cam=up,
        tilt_deg=tilt,
        roll_deg=roll,
        camera_height_m=sol.height_above_ankles_m + _ankle_over_soles_m(joints_cam_m, up),
        vp_rms_px=vp.rms_px,
        rms_px=sol.rms_px,
    )
    # an ill-conditioned single-view focal is no failure: the multi-view step recovers it (and says so if it cannot)
    uncertainty = (f"+-{100 * sol.focal_rel_uncertainty:.1f} %" if np.isfinite(sol.focal_rel_uncertainty)
                   else "undetermined")
    logger.info("view %d: single-view focal %.0f px (%s%s), tilt %.1f deg, camera %.2f m above the floor, %d/%d "
                "inliers", view, sol.fx_px, uncertainty, "; left to the multi-view step" if ill else "", tilt,
                estimate.camera_height_m, estimate.num_inliers, n)
    return estimate


def estimate_intrinsics(
    detections: DenseDetections,
    lifted: LiftedPoses,
    image_size_px: Sequence[tuple[int, int]],
    config: IntrinsicsConfig | None = None,
    principal_point_px: Sequence[tuple[float, float]] | None = None,
) -> list[IntrinsicsEstimate]:
    """Initial intrinsics of every view from its upright people.

    Args:
        detections: dense 2D detections of all views and frames.
        lifted: the lifted 3D pose of every detection (row-aligned; camera or crop frame: only lengths are used,
            plus the soles' height once the focal is known).
        image_size_px: per view ``(width, height)`` in pixels; its length is the number of views V.
        config: settings; defaults to :class:`IntrinsicsConfig`.
        principal_point_px: per view ``(cx, cy)`` when known; the image centre otherwise.

    Returns:
        One :class:`IntrinsicsEstimate` per view, in view order.

    Raises:
        ValueError: inconsistent inputs (row counts, view numbers, image sizes).
        CalibrationError: a view has no detections, or (with ``missing_upright="raise"``) no upright people.
    """
    config = config or IntrinsicsConfig()
    check_lifted(detections, lifted)
    sizes = [(int(w), int(h)) for w, h in image_size_px]
    V = len(sizes)
    if V == 0 or any(w <= 0 or h <= 0 for w, h in sizes):
        raise ValueError(f"image_size_px must list a positive (width, height) per view, got {sizes}")
    if len(detections) and (detections.view.min() < 0 or detections.view.max() >= V):
        raise ValueError(f"detections name views {sorted(set(detections.view.tolist()))} but there are {V} views")
    if principal_point_px is None:
        pps = [np.array([w / 2.0, h / 2.0]) for w, h in sizes]
    else:
        if len(principal_point_px) != V:
            raise ValueError(f"principal_point_px has {len(principal_point_px)} entries for {V} views")
        pps = [np.asarray(p, dtype=np.float64) for p in principal_point_px]
    rng = np.random.default_rng(config.seed)
    return [_estimate_view(v, detections, lifted, sizes[v], pps[v], config, rng) for v in range(V)]
