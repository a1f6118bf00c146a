"""Motion clips shared by the lifter tests: procedural motions of a few anny bodies (no external data)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from humancal.synthetic import generate_motions, sample_people


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """Tiny networks run fastest on one thread (two threads crawl when the other core is busy)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="session")
def motion_clips(body_model):
    """Six people, 150 frames (5 s) of random activities each, as (subject, keypoints_world_m) clips."""
    rng = np.random.default_rng(7)
    people = sample_people(body_model, 6, rng)
    rest = body_model.rest_skeleton(torch.as_tensor(people.phenotypes, dtype=body_model.dtype))
    with torch.no_grad():
        motions = generate_motions(body_model, rest, 150, 30.0, (6.0, 6.0), rng)
    return [(f"p{p}", motions.keypoints_world_m[p]) for p in range(6)]


@pytest.fixture(scope="session")
def train_val_clips(motion_clips):
    """Four training subjects, two held out."""
    return motion_clips[:4], motion_clips[4:]


@pytest.fixture(scope="session")
def tiny_training(train_val_clips):
    """One tiny training run: (checkpoint, history, progress records)."""
    from humancal.lifter import LifterConfig, train_lifter

    records = []
    train, val = train_val_clips
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        checkpoint, history = train_lifter(train, val, LifterConfig.tiny(), progress=records.append)
    finally:
        torch.set_num_threads(threads)
    return checkpoint, history, records
