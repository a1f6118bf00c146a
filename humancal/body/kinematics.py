"""Per-frame compact forward kinematics over the posed bones, and the exact linear keypoint map.

Pure tensor functions. Notation (``docs/body_model.md``): posed bone ``b`` has a world rotation ``G_b``
relative to the reference pose and a world head ``w_b``. In anny's "local-ref" parameterization with delta
rotation ``D_b`` (world-aligned axes), ``G_b = G_parent(b) @ D_b`` (root: ``G_0 = D_0``) and
``w_b = w_parent(b) + G_parent(b) @ offset_b`` (root: ``w_0`` = the root translation), where ``offset_b`` is
the head offset from the parent in the reference pose.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["ChainLevels", "chain_levels", "forward_kinematics", "keypoints_from_bones"]


@dataclass(frozen=True)
class ChainLevels:
    """A bone tree split into depth levels, for level-by-level forward kinematics.

    The bones must already be in depth order (root, then every depth-1 bone, then every depth-2 bone, ...), as
    SMPL's and humancal's posed bones are, so that each level is a contiguous run of bones and the levels
    together are a plain split of the bone axis (cheap to differentiate: no scatter in the backward pass).

    Attributes:
        sizes: number of bones in each level, the root's level (1) first.
        parent_slices: per level after the root, how its bones read their parents from the level before:
            ``(start, stop)`` when they are a contiguous run there, otherwise a LongTensor of positions.
    """

    sizes: tuple[int, ...]
    parent_slices: tuple[tuple[int, int] | Tensor, ...]

    def to(self, device: torch.device | str) -> "ChainLevels":
        """The same levels with every index tensor on ``device``."""
        return ChainLevels(
            self.sizes, tuple(p.to(device) if isinstance(p, Tensor) else p for p in self.parent_slices)
        )


def chain_levels(parents: Sequence[int]) -> ChainLevels:
    """Depth levels of a bone tree given in depth order.

    Args:
        parents: parent index of each bone (-1 for the root, which must be bone 0); every bone of depth d
            listed before every bone of depth d + 1.

    Raises:
        ValueError: bone 0 is not the single root, a parent comes after its child, or the bones are not in
            depth order.
    """
    if not parents or parents[0] != -1 or any(p < 0 or p >= i for i, p in enumerate(parents) if i > 0):
        raise ValueError(f"parents must list the root first (-1) and each parent before its child, got {list(parents)}")
    depth = [0] * len(parents)
    for i, p in enumerate(parents):
        if i > 0:
            depth[i] = depth[p] + 1
    if any(b < a for a, b in zip(depth, depth[1:])):
        raise ValueError(f"bones must be in depth order (all of depth d before depth d + 1), got depths {depth}")
    sizes = [depth.count(d) for d in range(max(depth) + 1)]
    starts = [sum(sizes[:d]) for d in range(len(sizes))]
    parent_slices: list[tuple[int, int] | Tensor] = []
    for d in range(1, len(sizes)):
        local = [parents[i] - starts[d - 1] for i in range(starts[d], starts[d] + sizes[d])]
        if local == list(range(local[0], local[0] + len(local))):
            parent_slices.append((local[0], local[0] + len(local)))
        else:
            parent_slices.append(torch.tensor(local))
    return ChainLevels(tuple(sizes), tuple(parent_slices))


def _parents_of(level: Tensor, parent_slice: tuple[int, int] | Tensor, dim: int) -> Tensor:
    if isinstance(parent_slice, Tensor):
        return level.index_select(dim, parent_slice)
    return level.narrow(dim, parent_slice[0], parent_slice[1] - parent_slice[0])


def forward_kinematics(
    delta_rotmats: Tensor,
    root_translation_m: Tensor,
    chain_offsets_m: Tensor,
    chain: ChainLevels,
) -> tuple[Tensor, Tensor]:
    """World rotations and heads of the posed bones from "local-ref" delta rotations.

    Args:
        delta_rotmats: (P, F, B, 3, 3) local-ref delta rotation of each bone (root: global orientation).
        root_translation_m: (P, F, 3) world position of the root head, metres.
        chain_offsets_m: (P, B, 3) head minus parent head in the reference pose, metres (root row unused).
        chain: :func:`chain_levels` of the tree, on the tensors' device.

    Returns:
        rotations: (P, F, B, 3, 3) world rotation of each bone relative to the reference pose (``G_b``).
        heads_m: (P, F, B, 3) world head positions, metres.
    """
    deltas = torch.split(delta_rotmats, chain.sizes, dim=-3)
    offsets = torch.split(chain_offsets_m[:, None, :, :, None], chain.sizes, dim=-3)
    level_rot = deltas[0]
    level_head = root_translation_m[..., None, :]
    rot_levels, head_levels = [level_rot], [level_head]
    # One batched product per depth level (7 levels for the 22 posed bones), not one per bone.
    for delta, offset, parent_slice in zip(deltas[1:], offsets[1:], chain.parent_slices):
        parent_rot = _parents_of(level_rot, parent_slice, -3)
        parent_head = _parents_of(level_head, parent_slice, -2)
        level_head = parent_head + (parent_rot @ offset)[..., 0]
        level_rot = parent_rot @ delta
        rot_levels.append(level_rot)
        head_levels.append(level_head)
    return torch.cat(rot_levels, dim=-3), torch.cat(head_levels, dim=-2)


def keypoints_from_bones(
    rotations: Tensor, heads_m: Tensor, keypoint_linear_m: Tensor, keypoint_affine: Tensor
) -> Tensor:
    """The exact keypoints as a linear function of the bones' world transforms.

    ``kp_k = sum_b (G_b @ keypoint_linear_m[k, b] + keypoint_affine[k, b] * w_b)``.

    Args:
        rotations: (P, F, B, 3, 3) world rotations ``G_b``.
        heads_m: (P, F, B, 3) world heads ``w_b``, metres.
        keypoint_linear_m: (P, K, B, 3) see :class:`humancal.body.RestSkeleton`.
        keypoint_affine: (P, K, B).

    Returns:
        (P, F, K, 3) keypoints, metres.
    """
    return torch.einsum("pfbij,pkbj->pfki", rotations, keypoint_linear_m) + torch.einsum(
        "pkb,pfbi->pfki", keypoint_affine, heads_m
    )
