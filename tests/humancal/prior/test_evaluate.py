"""Held-out evaluation of the motion prior: metrics, corruption, segments, reconstruction and the benchmark."""

from __future__ import annotations

import numpy as np
import pytest
import roma
import torch

from humancal.camera import project_points
from humancal.prior import MotionVAE, PriorConfig
from humancal.prior.evaluate import (
    RECONSTRUCTION_WINDOW,
    accel_error_mm_s2,
    corrupt_keypoints_2d,
    corrupt_keypoints_3d,
    denoise_method,
    denoising_benchmark,
    motion_segments,
    reconstruction_method,
    reconstruction_report,
    virtual_cameras,
)
from humancal.prior.latent_fit import FitConfig
from humancal.retarget import RetargetedClip


def _clip(body, name: str, frames: int, seed: int) -> RetargetedClip:
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(frames, dtype=torch.float64)[:, None, None] / 30.0
    rotvecs = 0.2 * torch.sin(2.0 * np.pi * t + 6.0 * torch.rand(1, 22, 3, generator=g, dtype=torch.float64))
    translation = torch.zeros(frames, 3, dtype=torch.float64)
    translation[:, 0] = 3.0 + t[:, 0, 0]
    translation[:, 2] = 0.95
    rotmats = roma.rotvec_to_rotmat(rotvecs)
    phenotypes = np.full(6, 0.5)
    with torch.no_grad():
        rest = body.rest_skeleton(torch.as_tensor(phenotypes, dtype=body.dtype)[None])
        keypoints = body.keypoints(rest, rotmats[None].to(body.dtype), translation[None].to(body.dtype))[0]
    return RetargetedClip(name=name, subject=name[:2], fps=30.0, phenotypes=phenotypes, bone_rotmats_local=rotmats.numpy(),
                          root_translation_m=translation.numpy(), keypoints_world_m=keypoints.double().numpy(),
                          joints_world_m=None, residual_mm=np.zeros((frames, 0)), mapped_joint_names=(),
                          offsets_m=np.zeros((0, 3)))


class _IdentityVAE(MotionVAE):
    """Latent = the 6D pose itself: reconstruction must be exact."""

    def __init__(self) -> None:
        super().__init__(PriorConfig.tiny().replace(latent_dim=126))

    def encode(self, pose6d):
        flat = pose6d.flatten(2)
        return flat, torch.zeros_like(flat)

    def decode(self, z):
        return z.reshape(*z.shape[:2], 21, 6)


def test_accel_error_is_zero_for_uniform_motion_and_scales_with_fps():
    t = np.arange(10.0)[:, None, None]
    gt = np.zeros((10, 2, 3))
    assert accel_error_mm_s2(gt + 0.1 * t + 0.5, gt, fps=30.0) == pytest.approx(0.0, abs=1e-9)
    quadratic = gt.copy()
    quadratic[..., 0] = 0.001 * t[..., 0] ** 2  # second difference 2 mm / frame^2 on every joint
    assert accel_error_mm_s2(quadratic, gt, fps=1.0) == pytest.approx(2.0)
    assert accel_error_mm_s2(quadratic, gt, fps=30.0) == pytest.approx(2.0 * 900)
    with pytest.raises(ValueError, match="T >= 3"):
        accel_error_mm_s2(gt[:2], gt[:2], 30.0)
    with pytest.raises(ValueError, match="fps"):
        accel_error_mm_s2(gt, gt, 0.0)


def test_method_names():
    assert reconstruction_method("motion_prior") == "motion_prior"
    assert reconstruction_method("no_skip") == "motion_prior/no_skip"
    assert denoise_method(None) == "denoise_no_prior"
    assert denoise_method("motion_prior") == "denoise_prior"
    assert denoise_method("per_frame") == "denoise_per_frame_prior"
    assert denoise_method("unidirectional") == "denoise_prior/unidirectional"


def test_3d_corruption_has_the_stated_noise_and_missing_share():
    clean = torch.zeros(4, 200, 23, 3, dtype=torch.float64)
    first = corrupt_keypoints_3d(clean, torch.Generator().manual_seed(1))
    again = corrupt_keypoints_3d(clean, torch.Generator().manual_seed(1))
    torch.testing.assert_close(first.points, again.points)
    assert float(first.points.std()) == pytest.approx(0.03, rel=0.03)
    assert float((~first.visible).double().mean()) == pytest.approx(0.2, abs=0.01)
    assert first.noise_scale == 0.03 and not first.is_2d


def test_virtual_cameras_and_2d_corruption():
    cameras = virtual_cameras()
    assert len(cameras) == 4
    for camera in cameras:
        centre = -camera.R_cam_from_world.T @ camera.t_cam_from_world_m
        assert np.hypot(*centre[:2]) == pytest.approx(6.0) and centre[2] == pytest.approx(1.5)
        px, _ = project_points(camera, np.array([[0.0, 0.0, 1.0]]))
        np.testing.assert_allclose(px[0], [959.5, 539.5], atol=1e-6)  # the aim point is the image centre
    points = torch.tensor(np.random.default_rng(0).normal(size=(1, 5, 23, 3)) * 0.3 + [0, 0, 1])
    clean = corrupt_keypoints_2d(points, cameras, torch.Generator().manual_seed(0), noise_px=0.0, missing=0.0)
    assert clean.is_2d and clean.points.shape == (4, 1, 5, 23, 2) and bool(clean.visible.all())
    expected, _ = project_points(cameras[2], points[0].reshape(-1, 3).numpy())
    np.testing.assert_allclose(clean.points[2, 0].reshape(-1, 2).numpy(), expected, atol=1e-6)


def test_segments_are_deterministic_centred_and_need_long_clips(body_model):
    clips = [_clip(body_model, "02_01", 40, 0), _clip(body_model, "02_02", 10, 1), _clip(body_model, "14_01", 30, 2)]
    segments = motion_segments(clips, frames=20, count=3, seed=4)
    assert [len(s.root_translation_m) for s in segments] == [20, 20, 20]
    assert {s.clip for s in segments} == {"02_01", "14_01"}  # 02_02 is too short
    again = motion_segments(clips, frames=20, count=3, seed=4)
    assert [(s.clip, s.start) for s in segments] == [(s.clip, s.start) for s in again]
    for s in segments:
        np.testing.assert_allclose(s.root_translation_m[:, :2].mean(axis=0), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="no clip has 50 frames"):
        motion_segments(clips, frames=50)


def test_the_reconstruction_windows_are_the_body_fits():
    from humancal.fitting import BodyFitConfig

    assert RECONSTRUCTION_WINDOW == (BodyFitConfig().window_frames, BodyFitConfig().window_overlap)


def test_reconstruction_is_exact_through_an_identity_autoencoder(body_model):
    clips = [_clip(body_model, "02_01", 12, 0), _clip(body_model, "14_01", 7, 1), _clip(body_model, "14_02", 75, 2)]
    for window in (RECONSTRUCTION_WINDOW, None):  # 75 frames: three windows of 32
        report = reconstruction_report(_IdentityVAE(), clips, body_model, window=window)
        assert report["mpjpe_mm"] == pytest.approx(0.0, abs=1e-3)
        assert report["accel_error_mm_s2"] == pytest.approx(0.0, abs=1e-1)
        assert report["frames"] == 94 and report["clips"] == 3
    torch.manual_seed(0)
    untrained = reconstruction_report(MotionVAE(PriorConfig.tiny()), clips, body_model)
    assert untrained["mpjpe_mm"] > 5.0  # the metric can fail
    with pytest.raises(ValueError, match="at least one clip"):
        reconstruction_report(_IdentityVAE(), [], body_model)


def test_denoising_benchmark_rows(body_model):
    clips = [_clip(body_model, "02_01", 10, 0), _clip(body_model, "14_01", 10, 1)]
    segments = motion_segments(clips, frames=8, count=2)
    torch.manual_seed(0)
    priors = {"per_frame": MotionVAE(PriorConfig.tiny("per_frame"))}
    configs = {"denoise_no_prior": FitConfig(iterations=3), "denoise_per_frame_prior": FitConfig(iterations=3)}
    table = denoising_benchmark(body_model, segments, priors, configs, setting="2d")
    assert list(table["method"]) == ["denoise_no_prior", "denoise_per_frame_prior"]
    assert (table["setting"] == "2d").all() and (table["frames"] == 8).all()
    assert np.isfinite(table[["mpjpe_mm", "accel_error_mm_s2", "fit_seconds"]].to_numpy()).all()
    with pytest.raises(ValueError, match="setting"):
        denoising_benchmark(body_model, segments, priors, configs, setting="4d")
