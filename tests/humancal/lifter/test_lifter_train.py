"""Training: loss goes down, runs are reproducible, checkpoints are plain and reloadable."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from humancal.lifter import (
    CHECKPOINT_FORMAT,
    LifterConfig,
    checkpoint_digest,
    checkpoint_num_bytes,
    load_lifter,
    train_lifter,
)
from humancal.lifter.infer import lift_features


def test_tiny_training_clearly_reduces_the_validation_loss(tiny_training):
    _, history, _ = tiny_training
    before, after = history[0], history[-1]
    assert before["val_loss_m"] > 0.5  # an untrained network is far off
    assert after["val_loss_m"] < 0.35 * before["val_loss_m"]
    assert after["val_mpjpe_mm"] < 350.0 and after["val_pa_mpjpe_mm"] < before["val_pa_mpjpe_mm"] - 100.0
    train_losses = [h["train_loss_m"] for h in history[1:]]
    assert train_losses[-1] < train_losses[0]


def test_history_progress_and_checkpoint_contents(tiny_training, train_val_clips):
    checkpoint, history, records = tiny_training
    config = LifterConfig.tiny()
    assert [h["epoch"] for h in history] == list(range(config.epochs + 1))
    assert np.isnan(history[0]["train_loss_m"]) and history[0]["steps"] == 0
    steps_per_epoch = -(-config.samples_per_epoch // config.batch_size)
    assert history[-1]["steps"] == steps_per_epoch * config.epochs
    step_records = [r for r in records if r["kind"] == "step"]
    assert [r["step"] for r in step_records] == list(range(10, history[-1]["steps"] + 1, 10))
    assert [r["epoch"] for r in records if r["kind"] == "epoch"] == list(range(config.epochs + 1))
    # Learning rate decays by cosine towards learning_rate * final_lr_factor.
    assert step_records[0]["lr"] > step_records[-1]["lr"] >= config.learning_rate * config.final_lr_factor
    assert checkpoint["format"] == CHECKPOINT_FORMAT
    assert checkpoint["train_subjects"] == ["p0", "p1", "p2", "p3"] and checkpoint["val_subjects"] == ["p4", "p5"]
    assert LifterConfig.from_dict(checkpoint["config"]) == config
    assert checkpoint["val_metrics"]["mpjpe_mm"] == pytest.approx(history[-1]["val_mpjpe_mm"])
    assert checkpoint_num_bytes(checkpoint) == 4 * sum(t.numel() for t in checkpoint["state_dict"].values())


def test_checkpoint_round_trips_through_a_weights_only_file(tiny_training, tmp_path):
    checkpoint, _, _ = tiny_training
    path = tmp_path / "lifter.pt"
    torch.save(checkpoint, path)
    reloaded = torch.load(path, weights_only=True)
    lifter_a, lifter_b = load_lifter(checkpoint), load_lifter(path)
    assert lifter_b.config == lifter_a.config and reloaded["format"] == CHECKPOINT_FORMAT
    features = np.random.default_rng(0).uniform(-1, 1, (16, 23, 3)).astype(np.float32)
    np.testing.assert_array_equal(lift_features(lifter_a.net, features), lift_features(lifter_b.net, features))


def test_training_is_deterministic_given_the_seed(train_val_clips):
    train, val = train_val_clips
    config = LifterConfig.tiny().replace(epochs=1, samples_per_epoch=1024, validation_samples=128)
    rng_state = torch.random.get_rng_state()
    first, history = train_lifter(train, val, config)
    assert torch.equal(torch.random.get_rng_state(), rng_state)  # the global torch RNG is left alone
    again, history_again = train_lifter(train, val, config)
    for name, tensor in first["state_dict"].items():
        assert torch.equal(tensor, again["state_dict"][name]), name
    assert [h["val_loss_m"] for h in history] == [h["val_loss_m"] for h in history_again]
    other, _ = train_lifter(train, val, config.replace(seed=1))
    assert not torch.equal(other["state_dict"]["head.weight"], first["state_dict"]["head.weight"])
    # the digest (the pipeline's data version) follows the weights, not the run time
    assert checkpoint_digest(first) == checkpoint_digest(again) != checkpoint_digest(other)
    assert config.digest() == LifterConfig.tiny().replace(epochs=1, samples_per_epoch=1024,
                                                          validation_samples=128).digest() != config.replace(seed=1).digest()


def test_subjects_must_not_be_shared_between_training_and_validation(train_val_clips):
    train, val = train_val_clips
    with pytest.raises(ValueError, match=r"subjects \['p0'\] are in both train_clips and val_clips"):
        train_lifter(train, [train[0]], LifterConfig.tiny())
    with pytest.raises(ValueError, match=r"val_clips must be a non-empty sequence"):
        train_lifter(train, [], LifterConfig.tiny())


def test_config_validation_and_round_trip():
    config = LifterConfig.default()
    assert LifterConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ValueError, match=r"LifterConfig.width must be an integer in \[8, 8192\], got 0"):
        LifterConfig(width=0)
    with pytest.raises(ValueError, match=r"LifterConfig.dropout must be a number in \[0, 0.9\], got 1.5"):
        config.replace(dropout=1.5)
    with pytest.raises(ValueError, match=r"LifterConfig has no field\(s\) \['widht'\]"):
        config.replace(widht=3)
    with pytest.raises(ValueError, match="not a LifterConfig dict"):
        LifterConfig.from_dict({"width": 3})
