"""Compact forward kinematics: level ordering and agreement with a bone-by-bone chain."""

import pytest
import roma
import torch

from humancal.body.kinematics import chain_levels, forward_kinematics


def test_chain_levels_rejects_bad_trees():
    with pytest.raises(ValueError, match="root first"):
        chain_levels([0, -1])
    with pytest.raises(ValueError, match="parent before its child"):
        chain_levels([-1, 2, 0])
    with pytest.raises(ValueError, match="root first"):
        chain_levels([])
    with pytest.raises(ValueError, match="depth order"):
        chain_levels([-1, 0, 1, 0])


def test_level_order_equals_bone_by_bone_chain():
    # Depth order; level 2 reads its parents through a gather (1, 1, 2), level 3 through a slice.
    parents = [-1, 0, 0, 1, 1, 2, 4, 5]
    generator = torch.Generator().manual_seed(0)
    deltas = roma.random_rotmat((2, 3, len(parents)), generator=generator)
    translations = torch.randn(2, 3, 3, generator=generator)
    offsets = torch.randn(2, len(parents), 3, generator=generator)
    rotations, heads = forward_kinematics(deltas, translations, offsets, chain_levels(parents))

    expected_rot = [deltas[:, :, 0]]
    expected_head = [translations]
    for bone, parent in enumerate(parents[1:], start=1):
        expected_head.append(expected_head[parent] + (expected_rot[parent] @ offsets[:, None, bone, :, None])[..., 0])
        expected_rot.append(expected_rot[parent] @ deltas[:, :, bone])
    torch.testing.assert_close(rotations, torch.stack(expected_rot, dim=2))
    torch.testing.assert_close(heads, torch.stack(expected_head, dim=2))
