"""The per-person rest skeleton: everything the per-frame keypoint path needs, computed once per shape."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import torch
from torch import Tensor

__all__ = ["RestSkeleton"]


@dataclass(frozen=True)
class RestSkeleton:
    """Per-person quantities of the body model that depend on shape only (not on pose).

    Built by :meth:`humancal.body.BodyModel.rest_skeleton`; differentiable w.r.t. the phenotypes it was built
    from. ``P`` people, ``B`` posed bones (``BodyModel.posed_bones``), ``K = 23`` canonical keypoints.

    The *reference pose* is the body with every posed-bone rotation at identity and the root head at the
    origin: it stands upright, facing -y, left side at +x, Z up (see ``docs/body_model.md``).

    Attributes:
        phenotypes: (P, 6) phenotype values in [0, 1], columns ``PHENOTYPE_NAMES``.
        bone_heads_m: (P, B, 3) heads of the posed bones in the reference pose, metres, root head at the origin.
        chain_offsets_m: (P, B, 3) head of each posed bone minus the head of its parent, in the reference pose,
            metres (root row: zeros).
        keypoint_linear_m: (P, K, B, 3) the part of each keypoint that rotates with posed bone ``b``:
            ``kp_k = sum_b (G_b @ keypoint_linear_m[k, b] + keypoint_affine[k, b] * head_b)`` with ``G_b`` the
            bone's world rotation relative to the reference pose and ``head_b`` its world head position, metres.
        keypoint_affine: (P, K, B) the summed regressor x skinning weight that follows the head of bone ``b``
            in keypoint ``k`` (each row sums to 1; shape-independent, expanded per person for convenience).
    """

    phenotypes: Tensor
    bone_heads_m: Tensor
    chain_offsets_m: Tensor
    keypoint_linear_m: Tensor
    keypoint_affine: Tensor

    @property
    def num_people(self) -> int:
        """Number of people P."""
        return int(self.phenotypes.shape[0])

    def select(self, people: Tensor | slice | list[int]) -> "RestSkeleton":
        """The rest skeletons of a subset of the people (index along the first dimension of every field)."""
        return RestSkeleton(**{f.name: getattr(self, f.name)[people] for f in fields(self)})

    def detach(self) -> "RestSkeleton":
        """The same skeletons cut from the autograd graph (e.g. for a fixed-shape stage of a fit)."""
        return RestSkeleton(**{f.name: getattr(self, f.name).detach() for f in fields(self)})

    def dominant_bones(self) -> Tensor:
        """(P, K) the posed bone each keypoint follows most (the largest ``keypoint_affine`` weight)."""
        return self.keypoint_affine.argmax(dim=-1)

    def with_keypoint_offsets(self, offsets_m: Tensor) -> "RestSkeleton":
        """The same skeletons with each keypoint moved by an offset that turns with its dominant bone.

        A detector trained on another definition of the joints (a hip centre placed elsewhere in the pelvis, say)
        sees every person's keypoint a little away from the body model's, by an offset fixed in the bone that
        carries it. With ``G_b`` the world rotation of keypoint ``k``'s dominant bone ``b`` relative to the
        reference pose, the keypoint becomes ``kp_k + G_b @ offsets_m[k]``.

        Args:
            offsets_m: (K, 3) or (P, K, 3) offsets in the axes of the reference pose (X to the body's left, Y to
                its back, Z up), metres; differentiable.

        Returns:
            A :class:`RestSkeleton` whose keypoints carry the offsets (every other field shared).
        """
        P, K, B, _ = self.keypoint_linear_m.shape
        if offsets_m.shape not in ((K, 3), (P, K, 3)):
            raise ValueError(f"offsets_m must have shape ({K}, 3) or ({P}, {K}, 3), got {tuple(offsets_m.shape)}")
        offsets = offsets_m.to(self.keypoint_linear_m).expand(P, K, 3)
        placed = torch.nn.functional.one_hot(self.dominant_bones(), B).to(offsets)  # (P, K, B)
        return replace(self, keypoint_linear_m=self.keypoint_linear_m + placed[..., None] * offsets[:, :, None, :])
