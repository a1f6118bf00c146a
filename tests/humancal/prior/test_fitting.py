"""Fitting motions to corrupted keypoints: the root initialization, the no-prior and the latent fits."""

from __future__ import annotations

import numpy as np
import pytest
import roma
import torch

from humancal.prior import MotionVAE, PriorConfig
from humancal.prior.evaluate import virtual_cameras
from humancal.prior.latent_fit import FitConfig, KeypointObservations, fit_motion, initial_root


def _smooth_motion(body, people: int, frames: int, seed: int = 0):
    """Rotations (P, T, 22, 3, 3) of slow sinusoidal bone motions, a turning root and a walking translation."""
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(frames, dtype=body.dtype)[None, :, None, None] / 30.0
    amplitude = 0.25 * torch.rand(people, 1, 22, 3, generator=g, dtype=body.dtype)
    phase = 6.0 * torch.rand(people, 1, 22, 3, generator=g, dtype=body.dtype)
    rotvecs = amplitude * torch.sin(2.0 * np.pi * 0.8 * t + phase)
    rotvecs[:, :, 0] = 0.0
    rotvecs[:, :, 0, 2] = 0.5 * t[..., 0, 0] + torch.arange(people, dtype=body.dtype)[:, None]  # turning about z
    translation = torch.zeros(people, frames, 3, dtype=body.dtype)
    translation[..., 0] = 1.2 * t[:, :, 0, 0]
    translation[..., 2] = 0.95
    return roma.rotvec_to_rotmat(rotvecs), translation


@pytest.fixture(scope="module")
def scene(body_model):
    phenotypes = torch.full((2, 6), 0.5, dtype=body_model.dtype)
    rest = body_model.rest_skeleton(phenotypes)
    rotmats, translation = _smooth_motion(body_model, 2, 12)
    with torch.no_grad():
        keypoints = body_model.keypoints(rest, rotmats, translation)
    return rest, rotmats, translation, keypoints


def test_initial_root_recovers_a_rigidly_moved_reference_pose(body_model, scene):
    rest, rotmats, translation, _ = scene
    P, T = translation.shape[:2]
    only_root = body_model.identity_pose(P, T)
    only_root[:, :, 0] = rotmats[:, :, 0]
    with torch.no_grad():
        keypoints = body_model.keypoints(rest, only_root, translation)
    visible = torch.ones(keypoints.shape[:-1], dtype=torch.bool)
    visible[0, 3, :7] = False  # head and shoulders missing: two usable points, the nearest frame's root is copied
    R, t = initial_root(body_model, rest, KeypointObservations(keypoints, visible, 0.03))
    assert R.shape == (P, T, 3, 3) and t.shape == (P, T, 3)
    good = torch.ones(P, T, dtype=torch.bool)
    good[0, 3] = False
    torch.testing.assert_close(R[good], rotmats[:, :, 0][good], atol=1e-4, rtol=0)
    torch.testing.assert_close(t[good], translation[good], atol=1e-4, rtol=0)
    torch.testing.assert_close(t[0, 3], t[0, 2])  # frames 2 and 4 are as near; the earlier one wins
    torch.testing.assert_close(R[0, 3], R[0, 2])


def test_initial_root_from_2d_views(body_model, scene):
    rest, rotmats, translation, _ = scene
    P, T = translation.shape[:2]
    only_root = body_model.identity_pose(P, T)
    only_root[:, :, 0] = rotmats[:, :, 0]
    centred = translation.clone()
    centred[..., :2] -= centred[..., :2].mean(dim=1, keepdim=True)
    with torch.no_grad():
        keypoints = body_model.keypoints(rest, only_root, centred)
    cameras = virtual_cameras()
    K, R, t = (torch.as_tensor(np.stack([getattr(c, n) for c in cameras]), dtype=body_model.dtype)
               for n in ("K", "R_cam_from_world", "t_cam_from_world_m"))
    x_cam = keypoints[None] @ R[:, None, None].transpose(-1, -2) + t[:, None, None, None]
    pixels = (x_cam[..., :2] / x_cam[..., 2:]) @ K[:, None, None, :2, :2].transpose(-1, -2) + K[:, None, None, None, :2, 2]
    observations = KeypointObservations(pixels, torch.ones(pixels.shape[:-1], dtype=torch.bool), 5.0, cameras)
    R_root, t_root = initial_root(body_model, rest, observations)
    torch.testing.assert_close(R_root, rotmats[:, :, 0], atol=1e-3, rtol=0)
    torch.testing.assert_close(t_root, centred, atol=1e-3, rtol=0)


@pytest.mark.slow  # an optimisation of tens of steps through the body model: ~5-10 s
def test_no_prior_fit_reproduces_clean_keypoints(body_model, scene):
    rest, _, _, keypoints = scene
    visible = torch.ones(keypoints.shape[:-1], dtype=torch.bool)
    result = fit_motion(body_model, rest, KeypointObservations(keypoints, visible, 0.03),
                        FitConfig(iterations=80, learning_rate=0.08, weight_root_smooth=0.0))
    error_mm = 1000 * (result.keypoints_m - keypoints).norm(dim=-1)
    assert error_mm.mean() < 10.0
    assert result.latents is None
    assert result.bone_rotmats_local.shape == (2, 12, 22, 3, 3)
    torch.testing.assert_close(body_model.keypoints(rest, result.bone_rotmats_local, result.root_translation_m),
                               result.keypoints_m)


def test_missing_keypoints_are_ignored(body_model, scene):
    rest, _, _, keypoints = scene
    visible = torch.ones(keypoints.shape[:-1], dtype=torch.bool)
    visible[:, :, 9] = False  # left wrist never seen: its (absurd) observation must not pull the fit
    moved = keypoints.clone()
    moved[:, :, 9] += 5.0
    config = FitConfig(iterations=15)
    far = fit_motion(body_model, rest, KeypointObservations(moved, visible, 0.03), config)
    near = fit_motion(body_model, rest, KeypointObservations(keypoints, visible, 0.03), config)
    torch.testing.assert_close(far.keypoints_m, near.keypoints_m)


@pytest.mark.slow  # an optimisation of tens of steps through the body model: ~5-10 s
def test_latent_fit_leaves_the_prior_untouched_and_lowers_the_objective(body_model, scene):
    rest, _, _, keypoints = scene
    torch.manual_seed(0)
    prior = MotionVAE(PriorConfig.tiny())
    before = {k: v.clone() for k, v in prior.state_dict().items()}
    observations = KeypointObservations(keypoints, torch.ones(keypoints.shape[:-1], dtype=torch.bool), 0.03)
    short = fit_motion(body_model, rest, observations, FitConfig(iterations=2), prior)
    longer = fit_motion(body_model, rest, observations, FitConfig(iterations=25), prior)
    assert longer.latents.shape == (2, 12, prior.latent_dim)
    assert longer.final_loss < short.final_loss
    for key, value in prior.state_dict().items():
        torch.testing.assert_close(value, before[key])


def test_bad_observations_name_the_field(body_model, scene):
    rest, _, _, keypoints = scene
    visible = torch.ones(keypoints.shape[:-1], dtype=torch.bool)
    with pytest.raises(ValueError, match="points must have shape"):
        KeypointObservations(keypoints[..., :2], visible, 0.03)
    with pytest.raises(ValueError, match="visible must be a bool tensor"):
        KeypointObservations(keypoints, visible.float(), 0.03)
    with pytest.raises(ValueError, match="noise_scale"):
        KeypointObservations(keypoints, visible, 0.0)
    with pytest.raises(ValueError, match="observations of 1 people"):
        fit_motion(body_model, rest, KeypointObservations(keypoints[:1], visible[:1], 0.03), FitConfig(iterations=1))
    with pytest.raises(ValueError, match="FitConfig.iterations"):
        FitConfig(iterations=0)
    with pytest.raises(ValueError, match="weight_latent"):
        FitConfig(weight_latent=-1.0)
    with pytest.raises(ValueError, match="no field"):
        FitConfig().replace(weight=1.0)
