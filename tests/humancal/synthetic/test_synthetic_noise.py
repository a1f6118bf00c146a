"""The detector noise model: realised error rates match the configured ones."""

from __future__ import annotations

import numpy as np
import pytest

from humancal.camera import project_points
from humancal.keypoints import FLIP_INDEX
from humancal.synthetic import JOINT_NOISE_WEIGHTS


def _true_pixels(scene):
    """(N, 23, 2) projections of the true joints of every real detection (in detected label order)."""
    d = scene.detector
    real = d.person_id >= 0
    out = np.full((d.num_detections, 23, 2), np.nan)
    for v, camera in enumerate(scene.rig):
        rows = np.flatnonzero(real & (d.view == v))
        out[rows] = project_points(camera, scene.keypoints_world_m[d.person_id[rows], d.frame[rows]])[0]
    flipped = np.flatnonzero(d.flipped)
    out[flipped] = out[flipped][:, FLIP_INDEX]
    return out


def _per_detection(scene, array):
    """Gather a (V, P, F, ...) truth array at every real detection."""
    d = scene.detector
    real = d.person_id >= 0
    return array[d.view[real], d.person_id[real], d.frame[real]], real


def _binomial_ok(successes, trials, p, sigmas=4.0):
    return abs(successes - trials * p) <= sigmas * np.sqrt(trials * p * (1 - p)) + 1


def test_jitter_std_scales_with_apparent_size(noisy_scene):
    noise = noisy_scene.config.noise
    d = noisy_scene.detector
    truth = _true_pixels(noisy_scene)
    occlusion, real = _per_detection(noisy_scene, d.occlusion)
    occlusion = np.where(d.flipped[real, None], occlusion[:, FLIP_INDEX], occlusion)
    scale, _ = _per_detection(noisy_scene, d.scale_px)
    residual = (d.keypoints_px[real] - truth[real]) / (scale[:, None, None] * JOINT_NOISE_WEIGHTS[None, :, None])
    clear = d.present[real] & (occlusion == 0.0)
    measured = residual[clear].std()
    assert clear.sum() > 20_000
    assert measured == pytest.approx(noise.jitter_std_frac, rel=0.05)
    hidden = d.present[real] & (occlusion == 1.0)
    assert hidden.sum() > 200
    assert residual[hidden].std() == pytest.approx(noise.jitter_std_frac * noise.occluded_jitter_factor, rel=0.15)


def test_flip_person_and_joint_miss_rates(noisy_scene):
    noise = noisy_scene.config.noise
    d = noisy_scene.detector
    real = d.person_id >= 0
    assert _binomial_ok(d.flipped[real].sum(), real.sum(), noise.flip_rate)
    eligible = d.eligible.sum()
    # Misses: random ones plus the few left with too few joints after joint misses.
    missed = eligible - d.detected.sum()
    assert missed >= eligible * noise.person_miss_rate - 4 * np.sqrt(eligible * 0.09)
    assert missed <= eligible * (noise.person_miss_rate + 0.02)
    assert not (d.detected & ~d.eligible).any()
    # Joint misses of clearly visible joints well inside the image.
    in_image, _ = _per_detection(noisy_scene, d.in_image)
    occlusion, _ = _per_detection(noisy_scene, d.occlusion)
    present = np.where(d.flipped[real, None], d.present[real][:, FLIP_INDEX], d.present[real])
    labelled = _true_pixels(noisy_scene)[real]
    truth = np.where(d.flipped[real, None, None], labelled[:, FLIP_INDEX], labelled)
    camera_size = np.array([[c.width_px, c.height_px] for c in noisy_scene.rig])[d.view[real]]
    inner = np.all((truth > 100.0) & (truth < camera_size[:, None, :] - 100.0), axis=-1)
    clear = in_image & inner & (occlusion == 0.0)
    assert _binomial_ok((~present[clear]).sum(), clear.sum(), noise.joint_miss_rate)
    hidden = in_image & inner & (occlusion == 1.0)
    assert _binomial_ok((~present[hidden]).sum(), hidden.sum(), noise.occluded_joint_miss_rate)


def test_false_positives_and_scores(noisy_scene):
    noise = noisy_scene.config.noise
    d = noisy_scene.detector
    fp = d.person_id < 0
    expected = noise.false_positives_per_image * noisy_scene.config.num_frames * len(noisy_scene.rig)
    # Some phantoms fall mostly outside the image and are dropped.
    assert 0.6 * expected < fp.sum() <= expected + 4 * np.sqrt(expected)
    assert (noisy_scene.associations.person_id == -1).sum() == fp.sum()
    assert d.present[fp].sum(axis=1).min() >= 2
    # Confidence: clear joints near score_mean, occluded ones lower by about occlusion_score_drop.
    occlusion, real = _per_detection(noisy_scene, d.occlusion)
    occlusion = np.where(d.flipped[real, None], occlusion[:, FLIP_INDEX], occlusion)
    scores, present = d.scores[real], d.present[real]
    truth = _true_pixels(noisy_scene)[real]
    camera_size = np.array([[c.width_px, c.height_px] for c in noisy_scene.rig])[d.view[real]]
    inner = np.all((truth > 100.0) & (truth < camera_size[:, None, :] - 100.0), axis=-1)
    clear = present & inner & (occlusion == 0.0)
    assert scores[clear].mean() == pytest.approx(noise.score_mean, abs=0.01)
    assert scores[clear].std() == pytest.approx(noise.score_std, rel=0.1)
    hidden = present & inner & (occlusion == 1.0)
    assert scores[hidden].mean() == pytest.approx(noise.score_mean - noise.occlusion_score_drop, abs=0.03)
    assert d.scores[fp][d.present[fp]].mean() < scores[clear].mean() - 0.2
