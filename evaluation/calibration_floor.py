"""What a self-calibration convention costs by itself: camera errors left with perfect detections.

A self-calibration that holds every principal point at the image centre (humancal's and the paper's), and gives
each view one focal length (square pixels: humancal's; the paper fits fx and fy), cannot represent a real camera
whose principal point is off centre or whose pixels are not square. Even from exact, noise-free projections of
known points, its best cameras are then off the true ones. Two measures of how far (ground truth only:
diagnostics, never a method path):

* :func:`self_calibration_floor`: the whole rig re-estimated at once under the convention, the way a
  self-calibration does it: every view's pose and focal length and every 3D point free, least squares on the exact
  projections of the true points, started at the truth. Scored with the benchmark's own protocol
  (:func:`evaluation.camera_metrics.camera_errors`: similarity alignment of the centres), so its figures are
  directly comparable with the ``init`` / ``int_ext`` rows. A calibration from real detections that lands below
  this floor does so by luck of its errors, not by what the images say. scipy is used rather than the body fit's
  bundle adjustment (:mod:`humancal.fitting.joint_bundle`) because the conventions compared include one it does not
  model (separate fx and fy); under humancal's convention the two land on the same rig (a test checks it).
* :func:`evaluation.camera_metrics.centred_principal_point_floor`: each true camera's pose alone re-estimated with a
  centred principal point (focal, other cameras and the points kept true; no alignment).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from evaluation.camera_metrics import CameraErrors, camera_errors
from humancal.camera import Camera, CameraRig, project_points

__all__ = ["self_calibration_floor"]


def _convention_intrinsics(camera: Camera, centred_principal_point: bool, square_pixels: bool) -> np.ndarray:
    """The true K as the convention can hold it: the principal point at the centre, one focal ``sqrt(fx fy)``."""
    K = camera.K.copy()
    if centred_principal_point:
        K[:2, 2] = (camera.width_px / 2.0, camera.height_px / 2.0)
    if square_pixels:
        K[0, 0] = K[1, 1] = np.sqrt(camera.K[0, 0] * camera.K[1, 1])
    return K


def self_calibration_floor(
    ground_truth: CameraRig,
    points_world_m: np.ndarray,
    *,
    centred_principal_point: bool = True,
    square_pixels: bool = True,
    free_focal: bool = True,
    free_k1: bool = False,
    max_points: int = 2000,
    seed: int = 0,
) -> CameraErrors:
    """Camera errors of the best rig under a calibration convention, from exact projections of known points.

    Every view's rotation, translation and (``free_focal``) focal scale, and every point, are fitted by scipy's
    ``least_squares`` (trust region, sparse Jacobian) to the noise-free projections of ``points_world_m`` through the
    true cameras (with their distortion; points behind a camera or outside its image are not seen by it). The
    model cameras keep the truth's distortion and, unless the convention replaces them, its principal point and
    focal lengths; the start is the truth (so without a convention change the floor is zero). The result is scored
    by :func:`~evaluation.camera_metrics.camera_errors` (similarity alignment of the centres).

    Args:
        ground_truth: V >= 2 true cameras.
        points_world_m: (N, 3) points the cameras see (e.g. ground-truth joints), metres; at least 6 finite.
        centred_principal_point: hold every principal point at the image centre.
        square_pixels: one focal length per view, ``sqrt(fx fy)`` of the truth at the start (False: fx and fy
            fitted separately, as the paper's intrinsics ``[fx, fy, w/2, h/2]``).
        free_focal: fit the focal lengths (False: held at the truth's, under the convention).
        free_k1: also fit each view's first radial distortion coefficient (humancal's lens option).
        max_points: at most this many points are used (a seeded random subset): the floor is a property of the
            rig and where people are, and a few thousand points fix it.
        seed: seed of that subset.

    Returns:
        :class:`~evaluation.camera_metrics.CameraErrors` with (V,) ``focal_error_pct``, ``position_error_mm``,
        ``angle_error_deg``, the ``alignment``, and ``residual_px`` (per view: the mean pixel distance left, how
        visible the convention's error is in the images) and ``cameras`` (the fitted rig).

    Raises:
        ValueError: fewer than 2 cameras or 6 finite points.
    """
    X = np.asarray(points_world_m, dtype=np.float64).reshape(-1, 3)
    X = X[np.isfinite(X).all(axis=1)]
    V = len(ground_truth)
    if V < 2 or len(X) < 6:
        raise ValueError(f"self_calibration_floor needs at least 2 cameras and 6 finite points, got {V} and {len(X)}")
    if len(X) > max_points:
        X = X[np.random.default_rng(seed).choice(len(X), size=max_points, replace=False)]
    N = len(X)
    seen, visible = [], []
    for cam in ground_truth:
        px, depth = project_points(cam, X)
        in_image = (px >= 0).all(-1) & (px < [cam.width_px, cam.height_px]).all(-1)
        inside = (depth > 0) & np.isfinite(px).all(-1) & in_image
        seen.append(np.where(inside[:, None], px, 0.0))
        visible.append(inside)
    seen_px, visible = np.stack(seen), np.stack(visible)  # (V, N, 2), (V, N)
    K_model = [_convention_intrinsics(c, centred_principal_point, square_pixels) for c in ground_truth]
    n_focal = 0 if not free_focal else 1 if square_pixels else 2  # log scales: one focal, or fx and fy
    n_cam = 6 + n_focal + int(free_k1)

    def cameras_of(x: np.ndarray) -> CameraRig:
        params = x[:n_cam * V].reshape(V, n_cam)
        out = []
        for v, cam in enumerate(ground_truth):
            K = K_model[v].copy()
            if n_focal:
                K[0, 0] *= np.exp(params[v, 6])
                K[1, 1] *= np.exp(params[v, 6 + n_focal - 1])
            distortion = cam.distortion.copy()
            if free_k1:
                distortion[0] += params[v, -1]
            out.append(Camera(K, cv2.Rodrigues(params[v, :3])[0], params[v, 3:6].copy(), cam.width_px,
                              cam.height_px, distortion))
        return CameraRig.from_cameras(out)

    def residuals(x: np.ndarray) -> np.ndarray:
        points = x[n_cam * V:].reshape(N, 3)
        out = []
        for v, cam in enumerate(cameras_of(x)):
            px, _ = project_points(cam, points)
            out.append(np.where(visible[v][:, None], np.nan_to_num(px - seen_px[v], nan=1e3), 0.0).ravel())
        return np.concatenate(out)

    start = [np.r_[cv2.Rodrigues(c.R_cam_from_world)[0].ravel(), c.t_cam_from_world_m, [0.0] * (n_focal + int(free_k1))]
             for c in ground_truth]
    x0 = np.concatenate([np.concatenate(start), X.ravel()])
    sparsity = lil_matrix((2 * V * N, len(x0)), dtype=np.int8)
    point_cols = n_cam * V + 3 * np.arange(N)
    for v in range(V):
        rows = 2 * N * v + np.arange(2 * N)
        sparsity[rows, n_cam * v:n_cam * (v + 1)] = 1
        for axis in range(2):
            for c in range(3):
                sparsity[rows[axis::2], point_cols + c] = 1
    fit = least_squares(residuals, x0, jac_sparsity=sparsity, x_scale="jac", method="trf", ftol=1e-12, xtol=1e-12,
                        gtol=1e-12, max_nfev=1000)
    cameras = cameras_of(fit.x)
    errors = camera_errors(cameras, ground_truth)
    r = np.linalg.norm(fit.fun.reshape(V, N, 2), axis=-1)
    errors["residual_px"] = np.array([r[v][visible[v]].mean() if visible[v].any() else np.nan for v in range(V)])
    errors["cameras"] = cameras
    return errors
