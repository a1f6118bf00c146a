"""The per-joint pieces of the simulated 2D pose detector (:mod:`humancal.synthetic.noise`): where a camera's lens
model is one-to-one, which pixels lie inside an image, the jitter of a detected joint and its confidence.
"""

from __future__ import annotations

import numpy as np

from humancal.camera import Camera
from humancal.synthetic.detector_noise import DetectorNoise
from humancal.synthetic.lenses import fold_radius

__all__ = [
    "JOINT_NOISE_WEIGHTS",
    "lens_fold_radius",
    "within_lens",
    "distort",
    "inside_image",
    "border_distance_px",
    "joint_scores",
    "jitter_px",
]

_COCO_SIGMAS = np.array(
    [0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062]
    + [0.107, 0.107, 0.087, 0.087, 0.089, 0.089]
    + [0.08] * 6
)
JOINT_NOISE_WEIGHTS: np.ndarray = _COCO_SIGMAS / _COCO_SIGMAS.mean()
"""(23,) relative jitter of each canonical joint: the COCO keypoint sigmas (foot points 0.08), mean 1."""


def lens_fold_radius(distortion: np.ndarray) -> float:
    """Undistorted radius (normalised image coordinates) where the camera's radial lens model stops growing
    (:func:`humancal.synthetic.lenses.fold_radius` of its k1, k2, k3), inf for an ideal pinhole."""
    k1, k2, _, _, k3 = np.asarray(distortion, dtype=np.float64)
    return fold_radius(k1, k2, k3)


def within_lens(camera: Camera, points_world_m: np.ndarray) -> np.ndarray:
    """(...,) whether each point lies inside the radius where the camera's lens model is one-to-one."""
    fold = lens_fold_radius(camera.distortion)
    if not np.isfinite(fold):
        return np.ones(points_world_m.shape[:-1], bool)
    x_cam = points_world_m @ camera.R_cam_from_world.T + camera.t_cam_from_world_m
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.hypot(x_cam[..., 0], x_cam[..., 1]) / x_cam[..., 2]
    return np.nan_to_num(r, nan=np.inf) < fold


def distort(uv: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """OpenCV lens distortion of normalised image points ``uv`` (N, J, 2) with per-row coefficients (N, 5)."""
    k1, k2, p1, p2, k3 = (distortion[:, i, None] for i in range(5))
    x, y = uv[..., 0], uv[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return np.stack(
        [
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        ],
        axis=-1,
    )


def inside_image(pixels_px: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """(...,) whether each pixel position (..., 2) lies inside a ``width_px`` x ``height_px`` image (False for NaN)."""
    x, y = pixels_px[..., 0], pixels_px[..., 1]
    with np.errstate(invalid="ignore"):
        return (x >= 0.0) & (x < width_px) & (y >= 0.0) & (y < height_px)


def border_distance_px(pixels_px: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """(...,) distance of each pixel position (..., 2) from the nearest image border, pixels (negative outside)."""
    x, y = pixels_px[..., 0], pixels_px[..., 1]
    return np.minimum(np.minimum(x, width_px - x), np.minimum(y, height_px - y))


def joint_scores(
    noise: DetectorNoise,
    noise_draw: np.ndarray,
    occlusion: np.ndarray,
    pixels_px: np.ndarray,
    scale_px: np.ndarray,
    camera: Camera,
) -> np.ndarray:
    """Confidences (P, F, 23) of real people's joints (step 5 of :mod:`humancal.synthetic.noise`)."""
    margin = np.maximum(noise.border_margin_frac * scale_px, 1e-6)[..., None]
    near_border = np.clip(1.0 - border_distance_px(pixels_px, camera.width_px, camera.height_px) / margin, 0.0, 1.0)
    score = noise.score_mean + noise.score_std * noise_draw - noise.occlusion_score_drop * occlusion
    score = score - noise.border_score_drop * np.nan_to_num(near_border, nan=1.0)
    return np.clip(score, 0.01, 1.0)


def jitter_px(
    noise: DetectorNoise,
    draws: np.ndarray,
    outlier: np.ndarray,
    outlier_draws: np.ndarray,
    occlusion: np.ndarray | float,
    scale_px: np.ndarray,
) -> np.ndarray:
    """Pixel offsets (..., 23, 2) from standard-normal ``draws`` (..., 23, 2), for apparent heights
    ``scale_px`` (...,) and occlusion degrees (..., 23); ``outlier`` (..., 23) marks gross outliers."""
    inflation = 1.0 + (noise.occluded_jitter_factor - 1.0) * occlusion
    std = noise.jitter_std_frac * JOINT_NOISE_WEIGHTS * scale_px[..., None] * inflation
    offsets = std[..., None] * draws
    outliers = noise.outlier_std_frac * scale_px[..., None, None] * outlier_draws
    return offsets + np.where(outlier[..., None], outliers, 0.0)
