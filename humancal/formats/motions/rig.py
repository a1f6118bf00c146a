"""anny's full rig for a person: rest mesh, inverse bind matrices, per-frame bone poses, skinning weights.

The glTF export skins anny's own mesh with anny's own 104-bone rig, so a glTF viewer reproduces anny's linear
blend skinning: with ``P_j`` the world pose of bone ``j`` (rotation and head) and ``B_j`` its rest pose, anny's
skinning transform is ``T_j = P_j @ inv(B_j)``, which is glTF's joint global transform times its inverse bind
matrix. Bones outside humancal's 22 posed bones keep the identity delta, so their transform relative to their
parent never changes: only the posed bones (and the five toe bones under each ``toes.*``) are animated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from humancal.body import BodyModel
from humancal.body.bones import ANNY_BONES_OF

__all__ = ["PersonRig", "animated_bones", "bone_world_poses", "local_transforms", "person_rig", "skin_weights"]


@dataclass(frozen=True)
class PersonRig:
    """One person's rig in humancal's world axes (Z up, metres).

    Attributes:
        bone_names: (J,) anny's bone labels (J = 104), parents before children.
        parents: (J,) parent bone index, -1 for the root.
        rest_vertices_m: (V, 3) anny's rest mesh for the person's shape (the bind pose).
        inverse_bind: (J, 4, 4) inverse of each bone's rest pose ``inv(B_j)``.
        rest_bone_poses: (J, 4, 4) the rest poses ``B_j`` (as torch, anny's dtype; for :func:`bone_world_poses`).
        reference_local: (J, 4, 4) each bone's transform relative to its parent in the reference pose (every
            delta identity, root head at the origin); root row: its world transform.
    """

    bone_names: tuple[str, ...]
    parents: tuple[int, ...]
    rest_vertices_m: np.ndarray
    inverse_bind: np.ndarray
    rest_bone_poses: torch.Tensor
    reference_local: np.ndarray


def animated_bones(bone_names: tuple[str, ...]) -> list[int]:
    """Indices of the anny bones whose local rotation moves with the pose (the bones humancal poses)."""
    driven = {name for group in ANNY_BONES_OF.values() for name in group}
    return [j for j, name in enumerate(bone_names) if name in driven]


def local_transforms(world: np.ndarray, parents: tuple[int, ...]) -> np.ndarray:
    """Transforms relative to the parent: ``inv(W_parent) @ W_j`` (root: ``W_root``).

    Args:
        world: (..., J, 4, 4) world poses.
        parents: (J,) parent indices, -1 for the root (bone 0).

    Returns:
        (..., J, 4, 4).
    """
    local = world.copy()
    parent_index = np.array(parents[1:])
    local[..., 1:, :, :] = np.linalg.inv(world[..., parent_index, :, :]) @ world[..., 1:, :, :]
    return local


def bone_world_poses(
    body: BodyModel, rig: PersonRig, bone_rotmats_local: np.ndarray, root_translation_m: np.ndarray, chunk: int = 512
) -> np.ndarray:
    """World pose of each of anny's bones per frame (anny's own kinematics, no mesh).

    Args:
        body: the body model.
        rig: the person's rig (:func:`person_rig`).
        bone_rotmats_local: (T, 22, 3, 3) posed-bone "local-ref" rotations.
        root_translation_m: (T, 3) root head positions, metres.
        chunk: frames per anny call.

    Returns:
        (T, J, 4, 4) float64; the head of bone j in frame t is ``[t, j, :3, 3]``.
    """
    out = []
    for start in range(0, bone_rotmats_local.shape[0], chunk):
        rot = torch.as_tensor(bone_rotmats_local[start : start + chunk], dtype=body.dtype, device=body.device)
        trans = torch.as_tensor(root_translation_m[start : start + chunk], dtype=body.dtype, device=body.device)
        pose = body.anny_pose_parameters(rot, trans)
        with torch.no_grad():
            _, poses = body.anny_model.get_bone_transforms(pose, rig.rest_bone_poses)
        out.append(poses.cpu().double().numpy())
    return np.concatenate(out) if out else np.zeros((0, len(rig.bone_names), 4, 4))


def person_rig(body: BodyModel, phenotypes: np.ndarray) -> PersonRig:
    """The rig of one person.

    Args:
        body: the body model.
        phenotypes: (6,) in [0, 1].
    """
    model = body.anny_model
    with torch.no_grad():
        coefficients = body.blendshape_coefficients(torch.as_tensor(phenotypes[None], dtype=body.dtype, device=body.device))
        rest = model.get_rest_model(coefficients)
    rest_bone_poses = rest["rest_bone_poses"]
    bone_names = tuple(model.bone_labels)
    parents = tuple(int(p) for p in model.bone_parents)
    rig = PersonRig(
        bone_names=bone_names, parents=parents,
        rest_vertices_m=rest["rest_vertices"][0].cpu().double().numpy(),
        inverse_bind=np.linalg.inv(rest_bone_poses[0].cpu().double().numpy()),
        rest_bone_poses=rest_bone_poses, reference_local=np.zeros((0,)),
    )
    reference = bone_world_poses(body, rig, np.eye(3)[None, None].repeat(body.num_posed_bones, 1), np.zeros((1, 3)))
    return PersonRig(**{**rig.__dict__, "reference_local": local_transforms(reference[0], parents)})


def skin_weights(body: BodyModel, max_influences: int = 8) -> tuple[np.ndarray, np.ndarray, float]:
    """anny's skinning weights, the largest ``max_influences`` per vertex, renormalised.

    Args:
        body: the body model.
        max_influences: influences kept per vertex (glTF: 4 per JOINTS_n/WEIGHTS_n set).

    Returns:
        joints: (V, max_influences) uint8 bone indices (zero where unused), largest weight first.
        weights: (V, max_influences) float32, each row summing to 1.
        dropped: the largest weight left out (0 when anny has no more influences than kept).
    """
    weights = body.anny_model.vertex_bone_weights.detach().cpu().double().numpy()
    indices = body.anny_model.vertex_bone_indices.detach().cpu().numpy()
    order = np.argsort(-weights, axis=1, kind="stable")
    weights = np.take_along_axis(weights, order, axis=1)
    indices = np.take_along_axis(indices, order, axis=1)
    dropped = float(weights[:, max_influences:].max()) if weights.shape[1] > max_influences else 0.0
    if weights.shape[1] < max_influences:
        pad = max_influences - weights.shape[1]
        weights = np.pad(weights, ((0, 0), (0, pad)))
        indices = np.pad(indices, ((0, 0), (0, pad)))
    weights, indices = weights[:, :max_influences], indices[:, :max_influences]
    weights = weights / weights.sum(axis=1, keepdims=True)
    indices = np.where(weights > 0, indices, 0)
    if indices.max() > 255:
        raise ValueError(f"anny rig has {indices.max() + 1} bones; the glTF writer stores joint indices as uint8")
    return indices.astype(np.uint8), weights.astype(np.float32), dropped
