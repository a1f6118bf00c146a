"""Lifter weights files: the safetensors + JSON pair round-trips, refuses damaged or mixed-up pairs, and the
shipped pair is a real CMU-trained lifter that lifts held-out motion well."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from evaluation.metrics import pa_mpjpe_mm
from humancal.lifter import (
    SHIPPED_LIFTER_STEM,
    LifterConfig,
    LifterWeightsError,
    SampleConfig,
    checkpoint_digest,
    lift_detections,
    load_lifter,
    read_lifter_info,
    read_lifter_weights,
    shipped_checkpoint,
    shipped_info,
    synthesize_samples,
    write_lifter_weights,
)


def test_round_trip_keeps_weights_config_and_digest(tiny_training, tmp_path):
    checkpoint = tiny_training[0]
    sidecar = write_lifter_weights(checkpoint, tmp_path / "lifter", {"trained_with": "a test"})
    back = read_lifter_weights(tmp_path / "lifter.safetensors")
    assert sidecar["digest"] == checkpoint_digest(checkpoint) == checkpoint_digest(back)
    assert LifterConfig.from_dict(back["config"]) == LifterConfig.from_dict(checkpoint["config"])  # JSON: lists
    assert back["train_subjects"] == checkpoint["train_subjects"]
    for name, tensor in checkpoint["state_dict"].items():
        assert torch.equal(back["state_dict"][name], tensor)
    assert read_lifter_info(tmp_path / "lifter")["trained_with"] == "a test"
    load_lifter(back)  # builds the network


def test_changed_weights_are_refused_naming_the_file(tiny_training, tmp_path):
    write_lifter_weights(tiny_training[0], tmp_path / "a")
    other = dict(tiny_training[0], state_dict={k: v + 1e-3 for k, v in tiny_training[0]["state_dict"].items()})
    write_lifter_weights(other, tmp_path / "b")
    (tmp_path / "b.json").replace(tmp_path / "a.json")  # a's weights with b's sidecar
    with pytest.raises(LifterWeightsError, match=r"a\.safetensors.*does not match field 'digest'"):
        read_lifter_weights(tmp_path / "a")


@pytest.mark.parametrize("damage", ["truncate", "missing_sidecar", "bad_json", "wrong_format"])
def test_damaged_pairs_are_refused(tiny_training, tmp_path, damage):
    write_lifter_weights(tiny_training[0], tmp_path / "lifter")
    tensors, sidecar = tmp_path / "lifter.safetensors", tmp_path / "lifter.json"
    if damage == "truncate":
        tensors.write_bytes(tensors.read_bytes()[:100])
    elif damage == "missing_sidecar":
        sidecar.unlink()
    elif damage == "bad_json":
        sidecar.write_text("{not json")
    else:
        sidecar.write_text(json.dumps(dict(json.loads(sidecar.read_text()), format="something/else")))
    with pytest.raises(LifterWeightsError, match="lifter"):
        read_lifter_weights(tmp_path / "lifter")


def test_shipped_weights_are_the_cmu_trained_default_configuration():
    info = shipped_info()
    assert LifterConfig.from_dict(info["config"]) == LifterConfig.default()
    assert info["val_subjects"] == ["02", "14"] and "02" not in info["train_subjects"]
    assert len(info["train_subjects"]) >= 10
    checkpoint = shipped_checkpoint()  # verifies the digest
    assert checkpoint_digest(checkpoint) == info["digest"]
    assert SHIPPED_LIFTER_STEM.with_suffix(".safetensors").stat().st_size < 8e6


def test_shipped_lifter_lifts_unseen_bodies(train_val_clips):
    """Procedural motions of random anny bodies (never seen in training): root-relative PA-MPJPE well under
    the 100 mm that an untrained or broken network gives."""
    samples = synthesize_samples(train_val_clips[1], 400, SampleConfig(), np.random.default_rng(3))
    lifted = lift_detections(load_lifter(shipped_checkpoint()), samples.keypoints_px, samples.scores)
    error = pa_mpjpe_mm(lifted.joints_cam_m[lifted.valid], samples.targets_m[lifted.valid])
    assert error < 70.0, f"shipped lifter PA-MPJPE on procedural motion {error:.1f} mm"
