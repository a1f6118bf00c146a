"""Scenes shared by the synthetic-generator tests (generated once per session from the shared body model)."""

from __future__ import annotations

import pytest

from humancal.synthetic import DetectorNoise, generate_scene, preset


@pytest.fixture(scope="session")
def tiny_scene(body_model):
    """2 people, 3 views, 20 frames, default detector noise."""
    return generate_scene(preset("tiny"), body_model, sequence="tiny")


@pytest.fixture(scope="session")
def clean_scene(body_model):
    """A perfect detector on 3 people, 4 views, 60 frames (occlusions and frame edges still happen)."""
    config = preset("tiny_clean", num_people=3, num_views=4, num_frames=60, seed=11)
    return generate_scene(config, body_model, sequence="clean")


@pytest.fixture(scope="session")
def noisy_scene(body_model):
    """A moderately sized scene with exaggerated, known error rates for statistics."""
    noise = DetectorNoise(
        jitter_std_frac=0.01,
        occluded_jitter_factor=3.0,
        outlier_rate=0.0,
        score_mean=0.8,
        score_std=0.05,
        occlusion_score_drop=0.5,
        joint_miss_rate=0.05,
        occluded_joint_miss_rate=0.6,
        person_miss_rate=0.1,
        false_positives_per_image=0.5,
        flip_rate=0.1,
    )
    config = preset("demo", num_people=3, num_views=4, num_frames=150, seed=5, noise=noise)
    return generate_scene(config, body_model, sequence="noisy")
