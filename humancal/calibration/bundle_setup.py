"""The problem the calibration's bundle adjustment (:func:`~humancal.calibration.bundle.bundle_adjust`) solves, set up
from its arguments: the starting values checked, the groups' observations and lifted poses weighted, the camera
blocks it starts from and which of their parameters move."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from humancal.calibration.bundle_terms import _camera_params, _focal_count, _focal_parameters, _Problem
from humancal.calibration.types import CalibrationError
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = ["BundleSetup", "bundle_setup", "check_start", "free_parameters", "start_cameras"]

logger = logging.getLogger("humancal.calibration.bundle")


def check_start(fx0, fy0, pp, bounds, R_init, t_init) -> None:
    """Raise :class:`CalibrationError` naming the views whose starting focal (V,), principal point (V, 2), focal
    bounds (V, 2), rotation (V, 3, 3) or translation (V, 3) is not finite (or a focal not positive), or bounds that
    are not low < high."""
    V = len(fx0)
    for name, values in (("focal", np.c_[fx0, fy0]), ("principal point", pp), ("focal bounds", bounds),
                         ("rotation", R_init.reshape(V, -1)), ("translation", t_init)):
        bad = np.flatnonzero(~np.isfinite(values).all(1) | ((values <= 0).any(1) if name == "focal" else False))
        if len(bad):
            raise CalibrationError(f"bundle adjustment: views {bad.tolist()} start with a non-finite or non-positive "
                                   f"{name}")
    if not (bounds[:, 0] < bounds[:, 1]).all():
        raise CalibrationError(f"bundle adjustment: focal bounds must be low < high, got {bounds.tolist()}")


@dataclass(frozen=True)
class BundleSetup:
    """The problem :func:`bundle_adjust` solves, and what its result reads besides.

    Attributes:
        prob: the observations, priors and bounds (:class:`~humancal.calibration.bundle_terms._Problem`).
        points: (G, 23, 3) starting keypoints, world metres (a group's missing ones at its centre).
        sigma_px: (S,) each grouped detection's pixel std (1 % of its body's extent, at least 1 px).
        observed: (O,) the grouped detection of each reprojection observation; detections: S, their number.
    """

    prob: _Problem
    points: np.ndarray
    sigma_px: np.ndarray
    observed: np.ndarray
    detections: int


def bundle_setup(detections: DenseDetections, lifted: LiftedPoses, groups: list[np.ndarray], points_world_m: np.ndarray,
           pp: np.ndarray, bounds: np.ndarray, *, square_pixels: bool, focal_prior_px, focal_prior_rel_std,
           shape_std_m: float, group_scale_std: float | None, min_score: float, huber: float, lens: bool,
           lens_prior_std: tuple[float, float, float]) -> BundleSetup:
    """The observations of the groups (confident keypoints, weighted by score over their detection's pixel std),
    their lifted poses, the focal priors and bounds (arguments as :func:`bundle_adjust`'s)."""
    V, G = len(pp), len(groups)
    X = np.asarray(points_world_m, dtype=np.float64).copy()
    finite_pts = np.isfinite(X).all(-1)
    empty = np.flatnonzero(~finite_pts.any(1))
    if len(empty):
        raise CalibrationError(f"bundle adjustment: groups {empty.tolist()[:10]} have no finite starting keypoint")
    centre = np.nanmean(np.where(finite_pts[..., None], X, np.nan), axis=1)
    X = np.where(finite_pts[..., None], X, centre[:, None])
    rows = np.concatenate(groups)
    grp = np.repeat(np.arange(G), [len(g) for g in groups])
    sc = detections.scores[rows]
    kp = detections.keypoints_px[rows]
    with np.errstate(invalid="ignore"):
        size = np.nanmax(np.linalg.norm(kp - np.nanmean(kp, 1, keepdims=True), axis=-1), axis=1)
    sigma_px = np.maximum(0.01 * 2.0 * np.nan_to_num(size), 1.0)  # size ~ half the body extent
    ok = (sc >= min_score) & np.isfinite(kp).all(-1)
    d_idx, j_idx = np.nonzero(ok)
    view = detections.view[rows]
    lifted_joints = lifted.joints_cam_m[rows]
    lifted_ok = np.isfinite(lifted_joints).all(-1)  # (S, 23): joints of NaN poses drop out of the shape term
    prior_f = np.zeros(V) if focal_prior_px is None else np.log(np.asarray(focal_prior_px, dtype=np.float64))
    prior_std = np.full(V, np.inf) if focal_prior_rel_std is None else np.asarray(focal_prior_rel_std, float)
    prior_w = np.where(np.isfinite(prior_std) & np.isfinite(prior_f), 1.0 / np.maximum(prior_std, 1e-3), 0.0)
    log_bounds = np.log(bounds)
    prob = _Problem(
        V=V, G=G, square=square_pixels,
        o_group=grp[d_idx], o_view=view[d_idx], o_joint=j_idx,
        o_px=kp[d_idx, j_idx] - pp[view[d_idx]],
        o_w=np.sqrt(sc[d_idx, j_idx]) / sigma_px[d_idx],
        s_group=grp, s_view=view, s_joints=np.where(lifted_ok[..., None], lifted_joints, 0.0),
        shape_w=lifted_ok / shape_std_m,
        log_f_mid=log_bounds.mean(1), log_f_half=0.5 * (log_bounds[:, 1] - log_bounds[:, 0]),
        prior_log_f=np.nan_to_num(prior_f), prior_w=prior_w, huber=huber,
        scale_w=1.0 / group_scale_std if group_scale_std else 0.0, free_scale=bool(group_scale_std),
        lens=lens,
        lens_prior_w=1.0 / np.asarray([lens_prior_std[0], lens_prior_std[1], lens_prior_std[2], lens_prior_std[2]],
                                      dtype=np.float64),
    )
    return BundleSetup(prob, X, sigma_px, d_idx, len(rows))


def start_cameras(prob: _Problem, fx0: np.ndarray, fy0: np.ndarray, t_init: np.ndarray, log_bounds: np.ndarray,
                   lens_start: np.ndarray | None) -> np.ndarray:
    """(V, nc) starting camera blocks: the bounded focal parameters (a start outside its bounds moves inside, with a
    warning), a zero rotation increment, the translations and the lens parameters (``lens_start`` or zeros)."""
    V, nf = prob.V, _focal_count(prob)
    log_f0 = np.log(np.c_[fx0] if prob.square else np.c_[fx0, fy0])
    if prob.square and not np.allclose(fx0, fy0):
        log_f0 = 0.5 * (np.log(np.c_[fx0]) + np.log(np.c_[fy0]))
    outside = np.flatnonzero(((log_f0 < log_bounds[:, :1]) | (log_f0 > log_bounds[:, 1:])).any(1))
    if len(outside):
        logger.warning("bundle adjustment: views %s start outside their focal bounds (%s px at %s px): started "
                       "inside", outside.tolist(), np.round(np.exp(log_f0[outside, 0])).tolist(),
                       np.round(np.exp(log_bounds[outside])).tolist())
    cams = np.zeros((V, _camera_params(prob)))
    cams[:, :nf] = _focal_parameters(prob, log_f0)
    cams[:, nf + 3 : nf + 6] = t_init
    if prob.lens:
        cams[:, nf + 6 :] = 0.0 if lens_start is None else np.asarray(lens_start, dtype=np.float64)
    return cams


def free_parameters(prob: _Problem, held: np.ndarray, adjust_cameras: bool, lens: str, principal_point: bool,
                     hold_lens_views: Sequence[int], hold_radial_views: Sequence[int] = ()) -> np.ndarray:
    """(V, nc) which camera parameters move: none of the ``held`` views' (V,), nor the pose of the first view not
    held (the world frame), nor the lens parameters the model or ``hold_lens_views`` fix, nor the radial terms of
    ``hold_radial_views``; none at all without ``adjust_cameras``."""
    nf = _focal_count(prob)
    free = np.ones((prob.V, _camera_params(prob)), bool)
    if not adjust_cameras:
        free[:] = False
    elif held.all():
        raise ValueError("bundle_adjust: every view is held; nothing to adjust")
    else:
        free[held] = False
        free[int(np.flatnonzero(~held)[0]), nf : nf + 6] = False  # the world frame
    if prob.lens:  # which lens parameters move: the model's, in views that are not held
        moving = np.array([lens != "pinhole", lens == "k1k2", principal_point, principal_point])
        free[:, nf + 6 :] &= moving[None]
        free[list(hold_lens_views), nf + 6 :] = False
        free[list(hold_radial_views), nf + 6 : nf + 8] = False
    return free
