"""How good the motion prior is on held-out subjects: reconstruction, and denoising / completion of corrupted clips.

Reconstruction (:func:`reconstruction_report`): every held-out clip, cut into the windows the body fit decodes
(:data:`RECONSTRUCTION_WINDOW`; or whole), encoded to its posterior means and decoded; the 23 canonical keypoints
of the decoded and of the original pose are compared through the body model with the root at the identity
orientation and the origin (the prior does not model the root), so the error is the body pose's alone.

Denoising and completion (:func:`denoising_benchmark`): fixed segments of held-out clips
(:func:`motion_segments`, each moved so that its mean root position is above the origin) are corrupted,

* ``3d``: the 23 keypoints with Gaussian noise (30 mm per coordinate) and 20 % of the keypoints missing
  (independently per frame and keypoint), or
* ``2d``: the same keypoints seen by four virtual cameras around the origin (:func:`virtual_cameras`: 6 m away,
  1.5 m high, 1000 px focal length) with 5 px Gaussian noise per coordinate (30 mm at 6 m) and 20 % missing per
  view,

and fitted with the known shapes (:func:`humancal.prior.latent_fit.fit_motion`): once through each prior's latents,
once through raw joint angles. Errors are against the clean keypoints, in the world frame (the root is fitted too).

Acceleration error: the mean over frames and keypoints of ``|| a_pred - a_true ||`` with ``a[t] = x[t+1] - 2 x[t]
+ x[t-1]``, converted from mm/frame^2 to mm/s^2 with the clip's frame rate (x fps^2: at 30 fps, 1 mm/frame^2 =
900 mm/s^2).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import torch
from torch import Tensor

from humancal.body import BodyModel
from humancal.camera import Camera, CameraRig, intrinsic_matrices, look_at
from humancal.geometry.pose_errors import mpjpe_mm
from humancal.prior.latent_fit import FitConfig, KeypointObservations, fit_motion
from humancal.prior.model import MotionVAE, pose6d_to_rotmats, rotmats_to_pose6d, with_root
from humancal.prior.windows import reconstruct_in_windows
from humancal.retarget import RetargetedClip

__all__ = [
    "DENOISE_FIT_CONFIGS",
    "DENOISE_MISSING",
    "DENOISE_NOISE_M",
    "DENOISE_NOISE_PX",
    "MotionSegment",
    "RECONSTRUCTION_WINDOW",
    "accel_error_mm_s2",
    "corrupt_keypoints_2d",
    "corrupt_keypoints_3d",
    "denoise_method",
    "denoising_benchmark",
    "motion_segments",
    "reconstruction_method",
    "reconstruction_report",
    "virtual_cameras",
]

log = logging.getLogger(__name__)

RECONSTRUCTION_WINDOW = (32, 6)
"""(frames, overlap) of the windows the reconstruction cuts clips into: those of the body fit
(``BodyFitConfig.window_frames``, ``window_overlap``), the way the product applies the prior. A prior trained on
16-frame windows may decode clips of hundreds of frames worse whole than in windows (``docs/motion_prior.md``)."""
DENOISE_NOISE_M = 0.03
"""Standard deviation of the 3D keypoint noise, metres per coordinate."""
DENOISE_MISSING = 0.2
"""Share of keypoints removed (per frame and keypoint; in 2D per view as well)."""
DENOISE_NOISE_PX = 5.0
"""Standard deviation of the 2D keypoint noise, pixels per coordinate: 30 mm at the virtual cameras' 6 m."""
_PRIOR_FIT = FitConfig(iterations=300, learning_rate=0.05, weight_latent=1e-3, weight_local_linear=300.0)
DENOISE_FIT_CONFIGS: dict[str, FitConfig] = {
    "denoise_no_prior": FitConfig(iterations=300, learning_rate=0.05, weight_rest=1e-4),
    "denoise_per_frame_prior": _PRIOR_FIT.replace(weight_local_linear=100.0),
    **{denoise_method_name: _PRIOR_FIT for denoise_method_name in (
        "denoise_prior", "denoise_prior/unidirectional", "denoise_prior/no_skip", "denoise_prior/no_local_linear")},
}
"""Fit configuration of each benchmark method, chosen on segments of training subjects (``scripts/eval_prior.py
--tune``), never on the held-out ones: for each prior the local-linear weight with the lowest MPJPE summed over
the 3D and 2D settings (300 for the default prior, 100 for the per-frame prior; 30 to 1000 tried, and 1 to 3000
with the 20-epoch priors, which both chose 100); the latent and rest weights changed nothing measurable. The other
variants take the default prior's weights."""
VIRTUAL_RIG = {"views": 4, "distance_m": 6.0, "height_m": 1.5, "focal_px": 1000.0, "size_px": (1920, 1080)}
"""The virtual cameras of the 2D setting."""


def reconstruction_method(variant: str) -> str:
    """Metric-table method of a variant's reconstruction rows: ``motion_prior`` or ``motion_prior/<variant>``."""
    return "motion_prior" if variant == "motion_prior" else f"motion_prior/{variant}"


def denoise_method(variant: str | None) -> str:
    """Metric-table method of a denoising fit: ``denoise_no_prior`` (None), ``denoise_prior`` (the default
    prior), ``denoise_per_frame_prior`` (the per-frame VAE), ``denoise_prior/<variant>`` (other variants)."""
    if variant is None:
        return "denoise_no_prior"
    if variant == "motion_prior":
        return "denoise_prior"
    if variant == "per_frame":
        return "denoise_per_frame_prior"
    return f"denoise_prior/{variant}"


# ---------------------------------------------------------------------------------------------------- metrics


def accel_error_mm_s2(pred_m: np.ndarray, gt_m: np.ndarray, fps: float) -> float:
    """Mean acceleration error (module docstring), mm/s^2.

    Args:
        pred_m, gt_m: (..., T, J, 3) keypoints in metres over T >= 3 consecutive frames.
        fps: frame rate, frames per second.

    Raises:
        ValueError: shapes differ, fewer than three frames, or fps <= 0.
    """
    pred_m, gt_m = np.asarray(pred_m, dtype=np.float64), np.asarray(gt_m, dtype=np.float64)
    if pred_m.shape != gt_m.shape or pred_m.ndim < 3 or pred_m.shape[-1] != 3 or pred_m.shape[-3] < 3:
        raise ValueError(f"accel_error_mm_s2 needs two (..., T >= 3, J, 3) arrays of one shape, got {pred_m.shape}, {gt_m.shape}")
    if not fps > 0:
        raise ValueError(f"accel_error_mm_s2: fps must be > 0, got {fps}")

    def accel(x: np.ndarray) -> np.ndarray:
        return x[..., 2:, :, :] - 2.0 * x[..., 1:-1, :, :] + x[..., :-2, :, :]

    per_frame_m = np.linalg.norm(accel(pred_m) - accel(gt_m), axis=-1)
    return float(1000.0 * per_frame_m.mean() * fps**2)


def _errors(pred_m: np.ndarray, gt_m: np.ndarray, fps: float) -> dict[str, float]:
    """MPJPE and acceleration error of (P, T, J, 3) keypoints."""
    flat = (-1, *pred_m.shape[-2:])
    return {"mpjpe_mm": mpjpe_mm(pred_m.reshape(flat), gt_m.reshape(flat)),
            "accel_error_mm_s2": accel_error_mm_s2(pred_m, gt_m, fps)}


# ---------------------------------------------------------------------------------------------------- reconstruction


@torch.no_grad()
def reconstruction_report(prior: MotionVAE, clips: Sequence[RetargetedClip], body: BodyModel,
                          window: tuple[int, int] | None = RECONSTRUCTION_WINDOW) -> dict[str, float]:
    """Encode (posterior means) and decode every clip; errors of the keypoints with the root at identity.

    Args:
        prior: the motion VAE.
        clips: the (held-out) clips; each needs at least three frames.
        body: the body model.
        window: (frames, overlap) of the windows each clip is cut into, as the body fit applies the prior
            (:func:`humancal.prior.windows.reconstruct_in_windows`); None encodes and decodes every clip whole.

    Returns:
        ``mpjpe_mm`` (mean over every frame and keypoint), ``accel_error_mm_s2`` (over every frame with two
        neighbours), ``frames``, ``clips``.

    Raises:
        ValueError: no clip.
    """
    if not clips:
        raise ValueError("reconstruction_report needs at least one clip")
    prior = prior.to(dtype=body.dtype, device=body.device).eval()
    to = dict(dtype=body.dtype, device=body.device)
    mpjpe_sum = accel_sum = 0.0
    frames = accel_frames = 0
    for clip in clips:
        rotmats = torch.as_tensor(np.array(clip.bone_rotmats_local), **to)[None]  # (1, T, 22, 3, 3)
        T = rotmats.shape[1]
        pose6d = rotmats_to_pose6d(rotmats[:, :, 1:])
        if window is None:
            decoded6d = prior.decode(prior.encode(pose6d)[0])
        else:
            decoded6d = reconstruct_in_windows(prior, pose6d, *window)
        eye = torch.eye(3, **to).expand(1, T, 3, 3)
        decoded = with_root(pose6d_to_rotmats(decoded6d), eye)
        original = with_root(rotmats[:, :, 1:], eye)
        rest = body.rest_skeleton(torch.as_tensor(np.array(clip.phenotypes), **to)[None])
        zero = torch.zeros(1, T, 3, **to)
        pred = body.keypoints(rest, decoded, zero).double().cpu().numpy()
        gt = body.keypoints(rest, original, zero).double().cpu().numpy()
        flat = (-1, *pred.shape[-2:])
        mpjpe_sum += mpjpe_mm(pred.reshape(flat), gt.reshape(flat)) * T
        frames += T
        if T >= 3:
            accel_sum += accel_error_mm_s2(pred, gt, clip.fps) * (T - 2)
            accel_frames += T - 2
    return {"mpjpe_mm": mpjpe_sum / frames, "accel_error_mm_s2": accel_sum / accel_frames if accel_frames else float("nan"),
            "frames": float(frames), "clips": float(len(clips))}


# ---------------------------------------------------------------------------------------------------- corruption


@dataclass(frozen=True)
class MotionSegment:
    """A stretch of a retargeted clip, moved so that its mean root position is above the origin.

    Attributes:
        clip: the clip's name; ``start``: its first frame in the clip; ``subject``; ``fps``.
        phenotypes: (6,) the subject's shape.
        bone_rotmats_local: (T, 22, 3, 3); root_translation_m: (T, 3) metres.
    """

    clip: str
    subject: str
    start: int
    fps: float
    phenotypes: np.ndarray
    bone_rotmats_local: np.ndarray
    root_translation_m: np.ndarray


def motion_segments(clips: Sequence[RetargetedClip], frames: int = 120, count: int = 16, seed: int = 0) -> list[MotionSegment]:
    """``count`` segments of ``frames`` frames, spread over the clips long enough for one (seeded choice).

    The clips are visited in turn (sorted by name, shuffled by the seed), one segment at a random start each,
    until ``count`` are drawn; a clip is visited again only when every clip has given one.

    Raises:
        ValueError: no clip has ``frames`` frames, or ``frames`` < 3, or ``count`` < 1.
    """
    if frames < 3 or count < 1:
        raise ValueError(f"motion_segments needs frames >= 3 and count >= 1, got frames={frames}, count={count}")
    long_enough = sorted((c for c in clips if len(c.root_translation_m) >= frames), key=lambda c: c.name)
    if not long_enough:
        raise ValueError(f"motion_segments: no clip has {frames} frames")
    rng = np.random.default_rng(seed)
    order = [long_enough[i] for i in rng.permutation(len(long_enough))]
    out = []
    for i in range(count):
        clip = order[i % len(order)]
        start = int(rng.integers(0, len(clip.root_translation_m) - frames + 1))
        translation = np.array(clip.root_translation_m[start : start + frames], dtype=np.float64)
        translation[:, :2] -= translation[:, :2].mean(axis=0)
        out.append(MotionSegment(clip.name, clip.subject, start, float(clip.fps), np.asarray(clip.phenotypes, np.float64),
                                 np.asarray(clip.bone_rotmats_local[start : start + frames], np.float64), translation))
    return out


def corrupt_keypoints_3d(keypoints_m: Tensor, generator: torch.Generator, noise_m: float = DENOISE_NOISE_M,
                         missing: float = DENOISE_MISSING) -> KeypointObservations:
    """Noisy keypoints with some missing.

    Args:
        keypoints_m: (P, T, 23, 3) clean keypoints, metres.
        generator: the source of the noise and of the missing keypoints.
        noise_m: noise standard deviation per coordinate, metres.
        missing: probability that a keypoint is missing.
    """
    noise = torch.randn(keypoints_m.shape, generator=generator, dtype=keypoints_m.dtype) * noise_m
    visible = torch.rand(keypoints_m.shape[:-1], generator=generator) >= missing
    scale = noise_m if noise_m > 0 else 0.01  # the data term's unit; noise-free data gets 1 cm
    return KeypointObservations(keypoints_m + noise.to(keypoints_m.device), visible.to(keypoints_m.device), scale)


def virtual_cameras(views: int = VIRTUAL_RIG["views"], distance_m: float = VIRTUAL_RIG["distance_m"],
                    height_m: float = VIRTUAL_RIG["height_m"], focal_px: float = VIRTUAL_RIG["focal_px"],
                    size_px: tuple[int, int] = VIRTUAL_RIG["size_px"]) -> CameraRig:
    """The rig of ``views`` pinhole cameras evenly around the origin, looking at a point 1 m above it."""
    width, height = size_px
    K = intrinsic_matrices(focal_px, focal_px, (width - 1) / 2.0, (height - 1) / 2.0)
    K = np.asarray(K).reshape(3, 3)
    cameras = []
    for v in range(views):
        angle = 2.0 * np.pi * v / views + np.pi / 4.0
        centre = np.array([distance_m * np.cos(angle), distance_m * np.sin(angle), height_m])
        R = look_at(centre, np.array([0.0, 0.0, 1.0]))
        cameras.append(Camera(K, R, -R @ centre, width, height))
    return CameraRig.from_cameras(cameras)


def corrupt_keypoints_2d(keypoints_m: Tensor, cameras: CameraRig, generator: torch.Generator,
                         noise_px: float = DENOISE_NOISE_PX, missing: float = DENOISE_MISSING) -> KeypointObservations:
    """The keypoints projected into each camera, with pixel noise and some missing in each view.

    Args:
        keypoints_m: (P, T, 23, 3) clean keypoints, metres.
        cameras: the rig of the V cameras.
        generator: the source of the noise and of the missing keypoints.
        noise_px: noise standard deviation per coordinate, pixels.
        missing: probability that a keypoint is missing in a view.
    """
    from humancal.camera.projection import project_points_torch

    to = dict(dtype=keypoints_m.dtype, device=keypoints_m.device)
    K, R, t = (torch.as_tensor(np.stack([getattr(c, n) for c in cameras]), **to)
               for n in ("K", "R_cam_from_world", "t_cam_from_world_m"))
    P, T, J, _ = keypoints_m.shape
    pixels, _, in_front = project_points_torch(keypoints_m.reshape(1, P * T * J, 3), K, R, t)
    V = len(cameras)
    pixels = pixels.reshape(V, P, T, J, 2)
    noise = torch.randn(pixels.shape, generator=generator, dtype=pixels.dtype).to(pixels.device) * noise_px
    visible = (torch.rand(pixels.shape[:-1], generator=generator) >= missing).to(pixels.device)
    visible = visible & in_front.reshape(V, P, T, J)
    scale = noise_px if noise_px > 0 else 1.0  # the data term's unit; noise-free data gets 1 px
    return KeypointObservations(pixels + noise, visible, scale, cameras)


# ---------------------------------------------------------------------------------------------------- benchmark


def _segment_tensors(body: BodyModel, segments: Sequence[MotionSegment]):
    to = dict(dtype=body.dtype, device=body.device)
    if len({len(s.root_translation_m) for s in segments}) != 1:
        raise ValueError("denoising_benchmark: every segment must have the same number of frames")
    rotmats = torch.as_tensor(np.stack([s.bone_rotmats_local for s in segments]), **to)
    translation = torch.as_tensor(np.stack([s.root_translation_m for s in segments]), **to)
    rest = body.rest_skeleton(torch.as_tensor(np.stack([s.phenotypes for s in segments]), **to))
    with torch.no_grad():
        clean = body.keypoints(rest, rotmats, translation)
    return rest, clean


def corrupted_observations(body: BodyModel, segments: Sequence[MotionSegment], setting: str, seed: int = 0):
    """The rest skeletons, clean keypoints (P, T, 23, 3) and the corrupted observations of one setting."""
    if setting not in ("3d", "2d"):
        raise ValueError(f"setting must be '3d' or '2d', got {setting!r}")
    rest, clean = _segment_tensors(body, segments)
    generator = torch.Generator().manual_seed(seed)
    if setting == "3d":
        return rest, clean, corrupt_keypoints_3d(clean, generator)
    return rest, clean, corrupt_keypoints_2d(clean, virtual_cameras(), generator)


def denoising_benchmark(
    body: BodyModel,
    segments: Sequence[MotionSegment],
    priors: Mapping[str, MotionVAE],
    configs: Mapping[str, FitConfig],
    setting: str = "3d",
    seed: int = 0,
    include_no_prior: bool = True,
) -> pd.DataFrame:
    """Fit corrupted segments with every prior and without one; errors against the clean keypoints.

    Args:
        body: the body model.
        segments: equally long segments (:func:`motion_segments`), fitted together as one batch.
        priors: variant name -> its motion VAE.
        configs: fit configuration by method (:func:`denoise_method` names); a method without one uses
            ``FitConfig()``.
        setting: ``"3d"`` or ``"2d"`` (module docstring).
        seed: seeds the corruption (the same corrupted data for every method).
        include_no_prior: also fit raw joint angles (method ``denoise_no_prior``).

    Returns:
        One row per method: ``method``, ``variant`` (None for the no-prior fit), ``setting``, ``mpjpe_mm``,
        ``accel_error_mm_s2``, ``fit_seconds``, ``segments``, ``frames`` (per segment).
    """
    rest, clean, observations = corrupted_observations(body, segments, setting, seed)
    fps = segments[0].fps
    gt = clean.double().cpu().numpy()
    runs: list[tuple[str | None, MotionVAE | None]] = [(None, None)] if include_no_prior else []
    runs += list(priors.items())
    rows = []
    for variant, prior in runs:
        method = denoise_method(variant)
        result = fit_motion(body, rest, observations, configs.get(method, FitConfig()), prior)
        errors = _errors(result.keypoints_m.double().cpu().numpy(), gt, fps)
        rows.append({"method": method, "variant": variant, "setting": setting, **errors,
                     "fit_seconds": result.seconds, "segments": len(segments), "frames": int(clean.shape[1])})
        log.info("%s (%s): MPJPE %.1f mm, accel %.0f mm/s^2 (%.0f s)", method, setting, errors["mpjpe_mm"],
                 errors["accel_error_mm_s2"], result.seconds)
    return pd.DataFrame(rows)
