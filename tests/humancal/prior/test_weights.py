"""Prior weights files: round trip, a clear PriorWeightsError for every kind of bad file, and the shipped prior."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file, save_file

from humancal.prior import (
    SHIPPED_PRIOR_STEM,
    SHIPPED_VARIANT_STEMS,
    MotionVAE,
    PriorConfig,
    PriorWeightsError,
    TrainedPrior,
    load_prior,
    pose_keypoints_m,
    pose6d_to_rotmats,
    read_prior_info,
    rotmats_to_pose6d,
    save_prior,
    shipped_prior,
)


def _trained(variant: str = "motion_prior", **changes) -> TrainedPrior:
    config = PriorConfig.tiny(variant).replace(**changes)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        model = MotionVAE(config).eval()
    return TrainedPrior(
        model=model, config=config, history=[{"epoch": 0, "train_loss": float("nan"), "val_mpjpe_mm": 200.0}],
        train_seconds=1.5, train_subjects=("s0",), held_out_subjects=("s1",),
        held_out={"mpjpe_mm": 200.0, "kl": 0.1, "windows": 8.0}, data_digest="d" * 64, num_train_frames=10,
    )


@pytest.fixture
def saved(tmp_path):
    trained = _trained()
    save_prior(trained, tmp_path / "prior", {"trained_with": "a test"})
    return trained, tmp_path / "prior"


def test_round_trip(saved):
    trained, stem = saved
    model, info = load_prior(stem.with_suffix(".safetensors"), variant="motion_prior")
    z = torch.randn(2, 6, trained.config.latent_dim, generator=torch.Generator().manual_seed(0))
    assert all(torch.equal(model.state_dict()[k], v) for k, v in trained.model.state_dict().items())
    with torch.no_grad():
        torch.testing.assert_close(model.decode(z), trained.model.decode(z), atol=1e-6, rtol=0)
    assert not any(p.requires_grad for p in model.parameters()) and not model.training
    assert info["config"] == trained.config.to_dict() and info["trained_with"] == "a test"
    assert info["history"][0]["train_loss"] is None  # NaN is not JSON: written as null
    assert info["held_out"]["mpjpe_mm"] == 200.0 and info["data_digest"] == "d" * 64
    assert read_prior_info(stem)["digest"] == info["digest"]


def test_missing_files(saved):
    _, stem = saved
    stem.with_suffix(".safetensors").unlink()
    with pytest.raises(PriorWeightsError, match=r"prior\.safetensors: motion-prior weights not found"):
        load_prior(stem)
    stem.with_suffix(".json").unlink()
    with pytest.raises(PriorWeightsError, match=r"prior\.json: motion-prior weights sidecar not found"):
        load_prior(stem)


def test_truncated_weights(saved):
    _, stem = saved
    path = stem.with_suffix(".safetensors")
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(PriorWeightsError, match=r"prior\.safetensors: not a readable safetensors file"):
        load_prior(stem)
    path.write_bytes(b"\x00\x01")
    with pytest.raises(PriorWeightsError, match=r"prior\.safetensors: not a readable safetensors file"):
        load_prior(stem)


def test_bad_sidecar(saved):
    _, stem = saved
    sidecar = stem.with_suffix(".json")
    info = json.loads(sidecar.read_text())
    sidecar.write_text(sidecar.read_text()[:40])
    with pytest.raises(PriorWeightsError, match=r"prior\.json: not a readable JSON sidecar"):
        load_prior(stem)
    sidecar.write_text(json.dumps({k: v for k, v in info.items() if k != "config"}))
    with pytest.raises(PriorWeightsError, match=r"prior\.json: missing field\(s\) \['config'\]"):
        load_prior(stem)
    sidecar.write_text(json.dumps({**info, "format": "humancal.lifter/1"}))
    with pytest.raises(PriorWeightsError, match=r"field 'format' is 'humancal.lifter/1'"):
        load_prior(stem)
    sidecar.write_text(json.dumps({**info, "config": {**info["config"], "variant": "lstm"}}))
    with pytest.raises(PriorWeightsError, match=r"prior\.json: field 'config' is not a valid PriorConfig"):
        load_prior(stem)


def test_wrong_variant_keys_and_shapes(saved, tmp_path):
    _, stem = saved
    with pytest.raises(PriorWeightsError, match=r"prior\.json: the weights are of variant 'motion_prior', expected 'no_skip'"):
        load_prior(stem, variant="no_skip")
    save_prior(_trained("per_frame"), tmp_path / "other")
    stem.with_suffix(".safetensors").write_bytes((tmp_path / "other.safetensors").read_bytes())
    with pytest.raises(PriorWeightsError, match=r"prior\.safetensors: tensor names differ from a 'motion_prior' MotionVAE"):
        load_prior(stem)
    save_prior(_trained(hidden_size=24), tmp_path / "wide")
    stem.with_suffix(".safetensors").write_bytes((tmp_path / "wide.safetensors").read_bytes())
    with pytest.raises(PriorWeightsError, match=r"prior\.safetensors: wrong tensor shapes: decoder\.gru\."):
        load_prior(stem)


def test_changed_weights_fail_the_digest(saved):
    _, stem = saved
    path = stem.with_suffix(".safetensors")
    state = load_file(str(path))
    state["mu_head.bias"] = state["mu_head.bias"] + 1e-3
    save_file(state, str(path))
    with pytest.raises(PriorWeightsError, match=r"prior\.safetensors: weights digest .* does not match field 'digest'"):
        load_prior(stem)


def test_shipped_prior_is_valid():
    model, info = shipped_prior()
    assert info["config"]["variant"] == "motion_prior" and model.latent_dim == 32
    # The issue asks for <= 15 mm; the shipped prior measures 14.1 mm on its 16-frame held-out windows
    # (docs/results/motion_prior.md).
    assert info["held_out"]["mpjpe_mm"] <= 15.0
    assert info["held_out_subjects"] == ["02", "14"] and not set(info["train_subjects"]) & {"02", "14"}
    assert len(info["history"]) == info["config"]["epochs"] + 1
    assert SHIPPED_PRIOR_STEM.with_suffix(".safetensors").stat().st_size < 20e6


def test_shipped_per_frame_prior_is_valid_and_unknown_variants_are_refused():
    model, info = shipped_prior("per_frame")
    assert info["config"]["variant"] == "per_frame" and model.latent_dim == 32 and not model.config.temporal
    assert info["held_out"]["mpjpe_mm"] <= 17.0  # measured 15.7 mm (docs/results/motion_prior.md)
    assert info["held_out_subjects"] == ["02", "14"] and not set(info["train_subjects"]) & {"02", "14"}
    with pytest.raises(PriorWeightsError, match=r"no shipped weights of the prior variant 'bidirectional_lstm'"):
        shipped_prior("bidirectional_lstm")


@pytest.mark.parametrize("variant, measured_mm", [("no_skip", 16.1), ("unidirectional", 15.6),
                                                  ("no_local_linear", 13.5)])
def test_shipped_ablation_priors_are_valid(variant, measured_mm):
    assert variant in SHIPPED_VARIANT_STEMS
    model, info = shipped_prior(variant)
    assert info["config"]["variant"] == variant and model.config.temporal
    assert info["held_out"]["mpjpe_mm"] <= measured_mm + 1.5  # docs/results/motion_prior.md
    assert info["held_out_subjects"] == ["02", "14"] and not set(info["train_subjects"]) & {"02", "14"}


REVERSAL_TOLERANCE_MM = 3.0
"""Mean keypoint distance allowed between decode(reversed latent) and the reversed decoding (shipped prior, on
these procedural motions: measured 1.74 mm, and 1.93 mm when the reversed motion is encoded; docs/results/motion_prior.md).
An exact equality cannot hold: the two GRU directions have their own weights; the reversal augmentation makes
the prior nearly symmetric in time."""


def test_reversed_latent_decodes_to_the_reversed_motion(body_model):
    """A bidirectional GRU is not exactly time-symmetric; trained with reversal augmentation it nearly is."""
    from humancal.synthetic import generate_motions, sample_people

    model, _ = shipped_prior()
    rng = np.random.default_rng(11)
    people = sample_people(body_model, 4, rng)
    rest = body_model.rest_skeleton(torch.as_tensor(people.phenotypes, dtype=body_model.dtype))
    with torch.no_grad():
        motions = generate_motions(body_model, rest, 64, 30.0, (6.0, 6.0), rng)
        bones = torch.as_tensor(motions.bone_rotmats_local[:, :, 1:], dtype=torch.float32)
        mu, _ = model.encode(rotmats_to_pose6d(bones))
        forward = pose_keypoints_m(body_model, rest, pose6d_to_rotmats(model.decode(mu)))
        backward = pose_keypoints_m(body_model, rest, pose6d_to_rotmats(model.decode(mu.flip(1))))
        reencoded, _ = model.encode(rotmats_to_pose6d(bones.flip(1)))
        backward_encoded = pose_keypoints_m(body_model, rest, pose6d_to_rotmats(model.decode(reencoded)))
    distance_mm = 1000 * torch.linalg.vector_norm(backward.flip(1) - forward, dim=-1).mean()
    encoded_mm = 1000 * torch.linalg.vector_norm(backward_encoded.flip(1) - forward, dim=-1).mean()
    assert float(distance_mm) < REVERSAL_TOLERANCE_MM, float(distance_mm)
    assert float(encoded_mm) < REVERSAL_TOLERANCE_MM, float(encoded_mm)
