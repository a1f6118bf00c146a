"""Training windows: slerp resampling, reversal, mirroring (an exact involution that mirrors the body)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import roma
import torch

from humancal.body.bones import POSED_BONE_NAMES
from humancal.keypoints import CANONICAL_JOINTS
from humancal.prior import (
    MIRROR_BONE_PERMUTATION,
    PriorConfig,
    clips_from_retargeted,
    mirror_bone_rotmats,
    sample_windows,
    slerp_rotmats,
)

OMEGA_RAD = 0.05
"""Angular speed of the test clips about z, radians per frame."""


def _spinning_clip(name: str, subject: str, frames: int) -> SimpleNamespace:
    """Every bone (root included) turning about z at OMEGA_RAD per frame: frame t is Rz(OMEGA_RAD * t)."""
    angles = OMEGA_RAD * torch.arange(frames, dtype=torch.float64)
    rotvec = torch.zeros(frames, 22, 3, dtype=torch.float64)
    rotvec[..., 2] = angles[:, None]
    return SimpleNamespace(
        name=name, subject=subject, fps=30.0, phenotypes=np.full(6, 0.5),
        bone_rotmats_local=roma.rotvec_to_rotmat(rotvec).numpy(),
    )


def _z_angles(bone_rotmats: torch.Tensor) -> torch.Tensor:
    """(..., 21, 3, 3) rotations about z -> their (..., 21) angles."""
    return torch.atan2(bone_rotmats[..., 1, 0].double(), bone_rotmats[..., 0, 0].double())


def _augment_only(**changes) -> PriorConfig:
    plain = {"resample_prob": 0.0, "reverse_prob": 0.0, "mirror_prob": 0.0}
    return PriorConfig.tiny().replace(**{**plain, **changes})


@pytest.fixture(scope="module")
def clips():
    return clips_from_retargeted([_spinning_clip("a", "s1", 60), _spinning_clip("b", "s2", 40)])


def _frame_steps(windows) -> torch.Tensor:
    return torch.diff(_z_angles(windows.bone_rotmats), dim=1)


def test_plain_windows_are_consecutive_frames(clips):
    windows = sample_windows(clips, 32, _augment_only(), np.random.default_rng(0))
    assert windows.bone_rotmats.shape == (32, 8, 21, 3, 3) and windows.bone_rotmats.dtype == torch.float32
    torch.testing.assert_close(_frame_steps(windows), torch.full((32, 7, 21), OMEGA_RAD, dtype=torch.float64),
                               atol=1e-6, rtol=0)
    # Plain windows start on a frame: their rotations are the clip's own, bit for bit.
    first = _z_angles(windows.bone_rotmats[:, 0, 0]) / OMEGA_RAD
    assert torch.allclose(first, first.round(), atol=1e-4)


def test_resampling_plays_at_the_drawn_speed(clips):
    for speed in (0.5, 2.0):
        config = _augment_only(resample_prob=1.0, speed_range=(speed, speed))
        windows = sample_windows(clips, 16, config, np.random.default_rng(1))
        steps = _frame_steps(windows)
        torch.testing.assert_close(steps, torch.full_like(steps, speed * OMEGA_RAD), atol=1e-5, rtol=0)
    fast = sample_windows(clips, 64, _augment_only(resample_prob=1.0, speed_range=(0.5, 2.0)), np.random.default_rng(2))
    speeds = _frame_steps(fast)[:, 0, 0] / OMEGA_RAD
    assert 0.5 - 1e-4 <= speeds.min() < 0.8 and 1.5 < speeds.max() <= 2.0 + 1e-4


def test_reversal_and_mirroring(clips):
    backwards = sample_windows(clips, 16, _augment_only(reverse_prob=1.0), np.random.default_rng(3))
    torch.testing.assert_close(_frame_steps(backwards), torch.full((16, 7, 21), -OMEGA_RAD, dtype=torch.float64),
                               atol=1e-6, rtol=0)
    # Mirroring across x -> -x turns a rotation about z the other way.
    mirrored = sample_windows(clips, 16, _augment_only(mirror_prob=1.0), np.random.default_rng(3))
    torch.testing.assert_close(_frame_steps(mirrored), torch.full((16, 7, 21), -OMEGA_RAD, dtype=torch.float64),
                               atol=1e-6, rtol=0)


def test_windows_are_deterministic_by_rng(clips):
    config = PriorConfig.tiny()
    a = sample_windows(clips, 20, config, np.random.default_rng(5))
    b = sample_windows(clips, 20, config, np.random.default_rng(5))
    c = sample_windows(clips, 20, config, np.random.default_rng(6))
    assert torch.equal(a.bone_rotmats, b.bone_rotmats) and np.array_equal(a.clip_index, b.clip_index)
    assert not torch.equal(a.bone_rotmats, c.bone_rotmats)


def test_slerp():
    R0 = roma.rotvec_to_rotmat(torch.tensor([[0.0, 0.0, 0.2]], dtype=torch.float64))
    R1 = roma.rotvec_to_rotmat(torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64))
    for w, angle in ((0.0, 0.2), (0.25, 0.4), (1.0, 1.0)):
        R = slerp_rotmats(R0, R1, torch.tensor([w], dtype=torch.float64))
        torch.testing.assert_close(R, roma.rotvec_to_rotmat(torch.tensor([[0.0, 0.0, angle]], dtype=torch.float64)))


def test_mirror_permutation_swaps_left_and_right():
    names = [POSED_BONE_NAMES[i] for i in MIRROR_BONE_PERMUTATION]
    for name, twin in zip(POSED_BONE_NAMES, names):
        expected = name.replace(".L", ".X").replace(".R", ".L").replace(".X", ".R")
        assert twin == expected
    assert sum(a != b for a, b in zip(POSED_BONE_NAMES, names)) == 16


@pytest.mark.parametrize("bones", [22, 21])
def test_mirroring_is_an_exact_involution(bones):
    R = roma.rotvec_to_rotmat(torch.randn(4, 6, bones, 3, generator=torch.Generator().manual_seed(0)))
    mirrored = mirror_bone_rotmats(R)
    assert not torch.allclose(mirrored, R)
    assert torch.equal(mirror_bone_rotmats(mirrored), R)
    assert np.array_equal(mirror_bone_rotmats(mirror_bone_rotmats(R.numpy())), R.numpy())
    torch.testing.assert_close(torch.linalg.det(mirrored), torch.ones(4, 6, bones))
    with pytest.raises(ValueError, match=r"\(\.\.\., 22, 3, 3\) or \(\.\.\., 21, 3, 3\)"):
        mirror_bone_rotmats(R[..., :20, :, :])


def test_mirroring_mirrors_the_body(body_model):
    """Keypoints of the mirrored pose = the pose's keypoints reflected (x -> -x) with left and right swapped."""
    generator = torch.Generator().manual_seed(1)
    R = roma.rotvec_to_rotmat(0.5 * torch.randn(1, 5, 22, 3, generator=generator))
    translation = torch.zeros(1, 5, 3)
    rest = body_model.rest_skeleton(torch.full((1, 6), 0.5))
    keypoints = body_model.keypoints(rest, R, translation)
    mirrored = body_model.keypoints(rest, mirror_bone_rotmats(R), translation)
    twin = [CANONICAL_JOINTS.index(n.replace("left", "x").replace("right", "left").replace("x", "right"))
            if ("left" in n or "right" in n) else i for i, n in enumerate(CANONICAL_JOINTS)]
    expected = keypoints[:, :, twin] * torch.tensor([-1.0, 1.0, 1.0])
    error_mm = 1000 * torch.linalg.vector_norm(mirrored - expected, dim=-1)
    # anny's mesh is symmetric up to a fraction of a millimetre (measured max 0.29 mm); a wrong axis or a
    # missing swap moves points by decimetres.
    assert float(error_mm.max()) < 2.0, float(error_mm.max())
    assert float(1000 * torch.linalg.vector_norm(mirrored - keypoints, dim=-1).mean()) > 50.0


def test_clip_validation():
    with pytest.raises(ValueError, match="clips is empty"):
        clips_from_retargeted([])
    bad = _spinning_clip("bad", "s1", 10)
    bad.bone_rotmats_local = bad.bone_rotmats_local[:, :21]
    with pytest.raises(ValueError, match=r"clip 'bad': bone_rotmats_local must have shape \(T, 22, 3, 3\)"):
        clips_from_retargeted([bad])
    clips = clips_from_retargeted([_spinning_clip("a", "s1", 20), _spinning_clip("b", "s2", 20)])
    train, held = clips.split_subjects(["s2"])
    assert train.names == ("a",) and held.names == ("b",) and held.starts.tolist() == [0, 20]
    with pytest.raises(ValueError, match=r"holding out subjects \['s3'\] leaves 2 training and 0 held-out"):
        clips.split_subjects(["s3"])
    with pytest.raises(ValueError, match="no clip has the 8 frames"):
        sample_windows(clips_from_retargeted([_spinning_clip("c", "s1", 5)]), 4, PriorConfig.tiny(),
                       np.random.default_rng(0))
