"""MotionVAE: shapes of every variant, any length, what each variant lets a frame see, and the 6D helpers."""

from __future__ import annotations

import pytest
import roma
import torch

from humancal.prior import (
    PRIOR_VARIANTS,
    MotionVAE,
    PriorConfig,
    identity_pose6d,
    pose6d_to_rotmats,
    rotmats_to_pose6d,
    with_root,
)


def _model(variant: str) -> MotionVAE:
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        return MotionVAE(PriorConfig.tiny(variant)).eval()


def _motion(batch: int, frames: int, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    rotvecs = 0.4 * torch.randn(batch, frames, 21, 3, generator=generator)
    return rotmats_to_pose6d(roma.rotvec_to_rotmat(rotvecs))


@pytest.mark.parametrize("variant", PRIOR_VARIANTS)
@pytest.mark.parametrize("frames", [1, 5, 16])
def test_shapes_of_every_variant(variant, frames):
    model = _model(variant)
    pose6d = _motion(3, frames)
    mu, logvar = model.encode(pose6d)
    assert mu.shape == logvar.shape == (3, frames, model.latent_dim)
    assert model.decode(mu).shape == (3, frames, 21, 6)
    assert model.decode_rotmats(mu).shape == (3, frames, 21, 3, 3)
    out = model(pose6d, generator=torch.Generator().manual_seed(1))
    assert out.pose6d.shape == (3, frames, 21, 6) and out.z.shape == mu.shape
    assert torch.equal(model(pose6d, sample=False).z, mu)


def test_default_sizes():
    model = MotionVAE(PriorConfig.default())
    assert model.latent_dim == 32
    mu, _ = model.encode(identity_pose6d().expand(1, 4, 21, 6))
    assert mu.shape == (1, 4, 32)


def test_bad_shapes_are_named():
    model = _model("motion_prior")
    with pytest.raises(ValueError, match=r"pose6d must have shape \(B, T, 21, 6\)"):
        model.encode(torch.zeros(2, 4, 22, 6))
    with pytest.raises(ValueError, match=r"z must have shape \(B, T, 8\)"):
        model.decode(torch.zeros(2, 4, 32))


def _changed_frames(model: MotionVAE, frames: int, at: int) -> list[int]:
    z = torch.randn(1, frames, model.latent_dim, generator=torch.Generator().manual_seed(3))
    bumped = z.clone()
    bumped[:, at] += 1.0
    with torch.no_grad():
        delta = (model.decode(bumped) - model.decode(z)).abs().flatten(2).amax(dim=2)[0]
    return [t for t in range(frames) if float(delta[t]) > 0.0]


def test_what_a_latent_frame_reaches_in_each_variant():
    assert _changed_frames(_model("per_frame"), 7, 3) == [3]
    assert _changed_frames(_model("unidirectional"), 7, 3) == [3, 4, 5, 6]
    assert _changed_frames(_model("motion_prior"), 7, 3) == list(range(7))
    assert _changed_frames(_model("no_skip"), 7, 3) == list(range(7))


def test_variant_switches():
    assert PriorConfig(variant="no_local_linear").local_linear_weight == 0.0
    assert PriorConfig(variant="per_frame").local_linear_weight == 0.0
    assert PriorConfig().local_linear_weight == PriorConfig().weight_local_linear > 0.0
    assert not PriorConfig(variant="no_skip").skip and PriorConfig().skip
    assert not PriorConfig(variant="unidirectional").bidirectional and PriorConfig().bidirectional
    skip_params = sum(p.numel() for p in _model("motion_prior").parameters())
    assert sum(p.numel() for p in _model("no_skip").parameters()) < skip_params


def test_config_validation_and_round_trip():
    with pytest.raises(ValueError, match=r"PriorConfig.variant='bidirectional' must be one of"):
        PriorConfig(variant="bidirectional")
    with pytest.raises(ValueError, match=r"PriorConfig.latent_dim must be an integer in \[1, 4096\], got 0"):
        PriorConfig(latent_dim=0)
    with pytest.raises(ValueError, match=r"PriorConfig.speed_range"):
        PriorConfig(speed_range=(2.0, 0.5))
    with pytest.raises(ValueError, match=r"no field\(s\) \['epoch'\]"):
        PriorConfig().replace(epoch=3)
    config = PriorConfig.tiny("no_skip", seed=4)
    assert PriorConfig.from_dict(config.to_dict()) == config
    assert config.digest() != PriorConfig.tiny("no_skip", seed=5).digest()
    with pytest.raises(ValueError, match=r"unknown field"):
        PriorConfig.from_dict({**config.to_dict(), "layers": 2})


def test_6d_round_trip_and_convention():
    R = roma.rotvec_to_rotmat(torch.randn(10, 3, generator=torch.Generator().manual_seed(0)))
    sixd = rotmats_to_pose6d(R)
    assert torch.equal(sixd, torch.stack([R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 0], R[:, 2, 1]], -1))
    torch.testing.assert_close(pose6d_to_rotmats(sixd), R, atol=1e-5, rtol=0)
    torch.testing.assert_close(pose6d_to_rotmats(identity_pose6d()), torch.eye(3).expand(21, 3, 3))


def test_6d_of_any_input_is_roma_gram_schmidt_with_gradients():
    # the conversion copies the columns to a contiguous layout for speed; the values must be roma's
    sixd = torch.randn(4, 7, 21, 6, dtype=torch.float64, generator=torch.Generator().manual_seed(1), requires_grad=True)
    ours = pose6d_to_rotmats(sixd)
    theirs = roma.special_gramschmidt(sixd.reshape(4, 7, 21, 3, 2))
    torch.testing.assert_close(ours, theirs, atol=1e-12, rtol=0)
    weights = torch.randn_like(ours)
    (g_ours,) = torch.autograd.grad((ours * weights).sum(), sixd)
    (g_theirs,) = torch.autograd.grad((theirs * weights).sum(), sixd)
    torch.testing.assert_close(g_ours, g_theirs, atol=1e-10, rtol=0)


def test_with_root():
    bones = torch.eye(3).expand(2, 5, 21, 3, 3)
    root = roma.rotvec_to_rotmat(torch.randn(2, 5, 3))
    full = with_root(bones, root)
    assert full.shape == (2, 5, 22, 3, 3) and torch.equal(full[:, :, 0], root)
    with pytest.raises(ValueError, match="with_root needs"):
        with_root(bones, root[:, :4])
