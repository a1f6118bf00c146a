"""Reduce anny's skinned-mesh keypoint regressor to a few tensors per posed bone, exactly.

Why this is exact (``docs/body_model.md`` has the long form): the keypoints are a fixed linear regressor over
the vertices, the vertices are linear-blend skinned (no pose correctives in anny), and every anny bone that is
not articulated keeps the identity delta, so its skinning transform is its nearest articulated ancestor ``e``'s
rigid motion composed with a shape-only transform: ``T_j = Gamma_e @ Tref_j``. Hence

    kp_k = sum_e [ G_e @ m_ke + c_ke * w_e ]

with ``c_ke = sum_{j -> e} sum_i W_ki w_ij`` (shape independent) and
``m_ke = sum_{j -> e} (Aref_j s_kj + c_kj tref_j) - c_ke wref_e``, where ``s_kj = sum_i W_ki w_ij v_i`` is linear
in the phenotype blendshape coefficients and is precomputed here for the template and for each blendshape. The
articulated bones of one posed bone share its rotation, and the extra bones of a group (the toes) have their
heads placed by the parent posed bone, so the sum folds onto the posed bones: ``kp_k = sum_b [G_b @ L_kb +
C_kb * w_b]``. A person's rest skeleton is then a small contraction plus anny's own skeleton-only rest and
reference kinematics.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import roma
import torch
from torch import Tensor

from humancal.body.bones import POSED_BONE_SPEC
from humancal.body.kinematics import ChainLevels, chain_levels
from humancal.body.rest import RestSkeleton

__all__ = ["KeypointReduction", "build_reduction", "rest_bone_poses", "rest_skeleton_from_coefficients"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class KeypointReduction:
    """Shape-independent tensors of the exact keypoint map (built once per model).

    ``E`` articulated anny bones (the posed bones, ``toes.*`` expanded to their five toe bones), ``B`` posed
    bones, ``J`` anny bones that carry keypoint weight, ``K`` keypoints, ``C`` blendshape coefficients.

    Attributes:
        articulated_bones: (E,) LongTensor, anny bone index of each articulated bone.
        pose_index: (E,) LongTensor, the posed bone whose rotation each articulated bone takes.
        translation_owner: (E,) LongTensor, the posed bone whose head and rotation place each articulated
            bone's head: itself for the first bone of a group, its parent posed bone for the other toes.
        is_group_head: (E,) bool, the first anny bone of each posed bone's group.
        joint_bones: (B,) LongTensor, anny bone index of the first bone of each posed bone's group.
        posed_parents: (B,) posed-bone parent of each posed bone (-1 for the root).
        chain: depth levels of the posed-bone tree.
        weighted_bones: (J,) LongTensor of anny bone indices with non-zero keypoint weight.
        weighted_group: (J,) LongTensor, the articulated bone (index into E) each one follows.
        affine_kj: (K, J) ``c_kj = sum_i W_ki w_ij``.
        affine_ke: (K, E) ``c_ke``, the sum of ``c_kj`` over each articulated bone's followers.
        affine_kb: (K, B) ``c_ke`` summed by translation owner.
        linear_template: (K, J, 3) ``s_kj`` of the template mesh, metres.
        linear_basis: (C, K, J, 3) ``s_kj`` of each blendshape, metres per unit coefficient.
    """

    articulated_bones: Tensor
    pose_index: Tensor
    translation_owner: Tensor
    is_group_head: Tensor
    joint_bones: Tensor
    posed_parents: tuple[int, ...]
    chain: ChainLevels
    weighted_bones: Tensor
    weighted_group: Tensor
    affine_kj: Tensor
    affine_ke: Tensor
    affine_kb: Tensor
    linear_template: Tensor
    linear_basis: Tensor


def _nearest_in(bone: int, members: dict[int, int], parents: list[int]) -> int:
    """Index (into the articulated list) of the nearest articulated ancestor of ``bone``, itself included."""
    current = bone
    while current not in members:
        current = parents[current]
        if current < 0:
            raise ValueError(f"anny bone {bone} has no articulated ancestor; the root must be articulated")
    return members[current]


def build_reduction(model, regression_weights: Tensor) -> KeypointReduction:
    """Precompute the shape-independent tensors of the exact keypoint map.

    Args:
        model: an ``anny.Anny`` instance (default rig and topology, "local-ref", cached bone orientations).
        regression_weights: (K, V) dense keypoint regressor over the model's vertices.

    Raises:
        ValueError: a posed bone name is not in the rig, or the rig's structure differs from what the reduction
            assumes (parents before children, a single root).
    """
    rig = _articulated_rig(model)
    dtype, device = regression_weights.dtype, regression_weights.device
    # Work in float64: the reduced tensors are sums over thousands of vertices.
    W = regression_weights.to(torch.float64)
    skin = _skinning_matrix(model, W.shape[1], len(rig.parents), device)
    affine_all = W @ skin  # (K, 104)
    weighted = torch.nonzero((affine_all != 0).any(dim=0)).flatten()
    group = torch.tensor([_nearest_in(int(j), rig.members, rig.parents) for j in weighted], device=device)
    linear = _linear_terms(model, W, skin, weighted)
    affine = _affine_terms(affine_all[:, weighted], group, rig)
    logger.debug(
        "keypoint reduction: %d articulated bones, %d weighted anny bones, %d blendshapes",
        len(rig.articulated), len(weighted), linear.basis.shape[0],
    )
    return KeypointReduction(
        articulated_bones=torch.tensor(rig.articulated, device=device),
        pose_index=torch.tensor(rig.pose_index, device=device),
        translation_owner=torch.tensor(rig.translation_owner, device=device),
        is_group_head=torch.tensor(rig.is_group_head, device=device),
        joint_bones=torch.tensor([rig.articulated[e] for e in rig.group_heads], device=device),
        posed_parents=rig.posed_parents,
        chain=chain_levels(rig.posed_parents).to(device),
        weighted_bones=weighted,
        weighted_group=group,
        affine_kj=affine.kj.to(dtype),
        affine_ke=affine.ke.to(dtype),
        affine_kb=affine.kb.to(dtype),
        linear_template=linear.template.to(dtype),
        linear_basis=linear.basis.to(dtype),
    )


@dataclass(frozen=True)
class _ArticulatedRig:
    """anny's articulated bones grouped by posed bone (``E`` articulated bones, ``B`` posed bones), as index lists.

    Attributes:
        parents: parent of each anny bone (-1 for the root).
        articulated: (E,) anny bone index of each articulated bone, posed-bone groups in ``POSED_BONE_SPEC`` order.
        pose_index: (E,) the posed bone whose rotation each articulated bone takes.
        group_heads: (B,) position in ``articulated`` of each posed bone's first anny bone.
        members: position in ``articulated`` of each articulated anny bone.
        posed_parents: (B,) posed-bone parent of each posed bone (-1 for the root).
        is_group_head: (E,) the articulated bone is the first of its posed bone's group.
        translation_owner: (E,) the posed bone whose head and rotation place each articulated bone's head.
    """

    parents: list[int]
    articulated: list[int]
    pose_index: list[int]
    group_heads: list[int]
    members: dict[int, int]
    posed_parents: tuple[int, ...]
    is_group_head: list[bool]
    translation_owner: list[int]


def _articulated_rig(model) -> _ArticulatedRig:
    """Group anny's articulated bones by posed bone and check the rig has the structure the reduction folds."""
    labels = list(model.bone_labels)
    parents = [int(p) for p in model.bone_parents]
    index = {name: i for i, name in enumerate(labels)}
    missing = [b for _, bones in POSED_BONE_SPEC for b in bones if b not in index]
    if missing:
        raise ValueError(f"anny rig lacks the posed bone(s) {missing}; humancal.body.bones expects anny's default rig")

    articulated: list[int] = []
    pose_index: list[int] = []
    group_heads: list[int] = []
    for b, (_, bones) in enumerate(POSED_BONE_SPEC):
        group_heads.append(len(articulated))
        for name in bones:
            articulated.append(index[name])
            pose_index.append(b)
    if articulated[0] != 0:
        raise ValueError("the first posed bone must be anny's root bone (index 0)")
    members = {bone: e for e, bone in enumerate(articulated)}
    articulated_parents = [-1] + [_nearest_in(parents[bone], members, parents) for bone in articulated[1:]]
    posed_parents = [-1] + [pose_index[articulated_parents[group_heads[b]]] for b in range(1, len(group_heads))]
    # The folding of a group's extra bones into the parent's terms needs every articulated bone to hang
    # directly from the first bone of its parent posed bone's group.
    for e in range(1, len(articulated)):
        if articulated_parents[e] != group_heads[posed_parents[pose_index[e]]]:
            raise ValueError(
                f"posed bone groups must hang from the first bone of their parent group; anny bone "
                f"{labels[articulated[e]]!r} does not (humancal.body.bones.POSED_BONE_SPEC)"
            )
    is_group_head = [e in set(group_heads) for e in range(len(articulated))]
    owner = [pose_index[e] if is_group_head[e] else posed_parents[pose_index[e]] for e in range(len(articulated))]
    return _ArticulatedRig(
        parents, articulated, pose_index, group_heads, members, tuple(posed_parents), is_group_head, owner
    )


def _skinning_matrix(model, num_vertices: int, num_bones: int, device: torch.device) -> Tensor:
    """anny's sparse skinning weights as a dense (V, num_bones) float64 matrix ``w_ij``."""
    skin = torch.zeros(num_vertices, num_bones, dtype=torch.float64, device=device)
    skin.scatter_add_(1, model.vertex_bone_indices.long(), model.vertex_bone_weights.to(torch.float64))
    return skin


@dataclass(frozen=True)
class _LinearTerms:
    """``s_kj`` in float64: ``template`` (K, J, 3) of the template mesh, ``basis`` (C, K, J, 3) per blendshape."""

    template: Tensor
    basis: Tensor


def _linear_terms(model, W: Tensor, skin: Tensor, weighted: Tensor) -> _LinearTerms:
    """``s_kj = sum_i W_ki w_ij v_i`` for the template mesh and each blendshape, over the weighted bones.

    Args:
        model: the ``anny.Anny`` instance.
        W: (K, V) float64 keypoint regressor.
        skin: (V, 104) float64 skinning weights.
        weighted: (J,) anny bones with non-zero keypoint weight.
    """
    num_keypoints, device = W.shape[0], W.device
    # Only the vertices that some keypoint reads (about 8,800 of 13,718) matter.
    read = torch.nonzero((W != 0).any(dim=0)).flatten()
    W, skin = W[:, read], skin[read][:, weighted]
    template = model.template_vertices[read].to(torch.float64)
    num_coefficients = model.blendshapes.shape[0]
    # (n, C * 3): one row per vertex, so that a keypoint's vertices are a contiguous row gather.
    blendshapes = model.blendshapes[:, read].to(torch.float64).permute(1, 0, 2).reshape(len(read), -1)
    linear_template = torch.zeros(num_keypoints, len(weighted), 3, dtype=torch.float64, device=device)
    linear_basis = torch.zeros(num_coefficients, num_keypoints, len(weighted), 3, dtype=torch.float64, device=device)
    for k in range(num_keypoints):
        # Each keypoint reads a few hundred vertices and a few bones: contract over those only.
        vertices = torch.nonzero(W[k]).flatten()
        per_bone = W[k, vertices, None] * skin[vertices]  # (n_k, J)
        bones = torch.nonzero((per_bone != 0).any(dim=0)).flatten()
        per_bone = per_bone[:, bones]
        linear_template[k, bones] = per_bone.T @ template[vertices]
        linear_basis[:, k, bones] = (per_bone.T @ blendshapes[vertices]).reshape(len(bones), -1, 3).permute(1, 0, 2)
    return _LinearTerms(linear_template, linear_basis)


@dataclass(frozen=True)
class _AffineTerms:
    """The keypoint weight of each bone, float64: ``kj`` (K, J), ``ke`` (K, E) and ``kb`` (K, B)."""

    kj: Tensor
    ke: Tensor
    kb: Tensor


def _affine_terms(affine_kj: Tensor, group: Tensor, rig: _ArticulatedRig) -> _AffineTerms:
    """Sum ``c_kj`` (K, J) over each articulated bone's followers (``group``, (J,)), then by translation owner."""
    num_keypoints, device = affine_kj.shape[0], affine_kj.device
    affine_ke = torch.zeros(num_keypoints, len(rig.articulated), dtype=torch.float64, device=device)
    affine_ke.index_add_(1, group, affine_kj)
    affine_kb = torch.zeros(num_keypoints, len(POSED_BONE_SPEC), dtype=torch.float64, device=device)
    affine_kb.index_add_(1, torch.tensor(rig.translation_owner, device=device), affine_ke)
    return _AffineTerms(affine_kj, affine_ke, affine_kb)


def rest_bone_poses(model, coefficients: Tensor) -> Tensor:
    """anny's rest bone poses (P, 104, 4, 4) from blendshape coefficients, without the rest mesh.

    The same computation as anny's cached-orientation rest model (heads and orientation cross-covariances are
    linear in the coefficients; orientations are their special Procrustes), minus the (P, V, 3) vertices.
    """
    heads = model.template_bone_heads[None] + torch.einsum("pc,cjd->pjd", coefficients, model.bone_heads_blendshapes)
    covariances = model.bone_template_orientation_matrices[None] + torch.einsum(
        "pc,cjab->pjab", coefficients, model.bone_orientation_blendshapes
    )
    orientations = roma.special_procrustes(covariances)
    if model.root_identity_orientation:
        eye = torch.eye(3, dtype=orientations.dtype, device=orientations.device)
        orientations = torch.cat([eye.expand_as(orientations[:, :1]), orientations[:, 1:]], dim=1)
    return roma.Rigid(linear=orientations, translation=heads).to_homogeneous()


def rest_skeleton_from_coefficients(
    model, reduction: KeypointReduction, phenotypes: Tensor, coefficients: Tensor
) -> RestSkeleton:
    """Per-person rest skeleton (see :class:`RestSkeleton`) from the phenotype blendshape coefficients (P, C)."""
    num_people = coefficients.shape[0]
    rest = rest_bone_poses(model, coefficients)
    identity = torch.eye(4, dtype=rest.dtype, device=rest.device).expand_as(rest)
    # anny's own kinematics with identity deltas: the reference pose (root head at the origin).
    transforms_ref, poses_ref = model.get_bone_transforms(identity, rest)
    heads_ref = poses_ref[..., :3, 3]  # (P, 104, 3)

    r = reduction
    linear = r.linear_template[None] + torch.einsum("pc,ckjd->pkjd", coefficients, r.linear_basis)
    weighted_ref = transforms_ref.index_select(1, r.weighted_bones)
    rot_ref, trans_ref = weighted_ref[..., :3, :3], weighted_ref[..., :3, 3]  # (P, J, 3, 3), (P, J, 3)
    per_bone = torch.einsum("pjab,pkjb->pkja", rot_ref, linear) + r.affine_kj[None, :, :, None] * trans_ref[:, None]
    num_keypoints, num_articulated, num_posed = per_bone.shape[1], len(r.articulated_bones), len(r.joint_bones)
    per_articulated = per_bone.new_zeros(num_people, num_keypoints, num_articulated, 3)
    per_articulated = per_articulated.index_add(2, r.weighted_group, per_bone)
    heads_art = heads_ref.index_select(1, r.articulated_bones)  # (P, E, 3)
    # Rotating part: the articulated bone's own rotation (shared by its posed bone's group).
    linear_art = per_articulated - r.affine_ke[None, :, :, None] * heads_art[:, None]
    keypoint_linear = per_articulated.new_zeros(num_people, num_keypoints, num_posed, 3)
    keypoint_linear = keypoint_linear.index_add(2, r.pose_index, linear_art)
    # Translating part: a group's extra bones have their heads placed by the parent posed bone,
    # w_e = w_owner + G_owner (wref_e - wref_owner); fold that into the owner's terms.
    heads_posed = heads_ref.index_select(1, r.joint_bones)  # (P, B, 3)
    owner_offsets = heads_art - heads_posed[:, r.translation_owner]  # zero for group heads
    keypoint_linear = keypoint_linear.index_add(
        2, r.translation_owner, r.affine_ke[None, :, :, None] * owner_offsets[:, None]
    )
    parents = torch.tensor([0, *r.posed_parents[1:]], device=rest.device)
    chain_offsets = heads_posed - heads_posed[:, parents]
    return RestSkeleton(
        phenotypes=phenotypes,
        bone_heads_m=heads_posed,
        chain_offsets_m=chain_offsets,
        keypoint_linear_m=keypoint_linear,
        keypoint_affine=r.affine_kb[None].expand(num_people, -1, -1),
    )
