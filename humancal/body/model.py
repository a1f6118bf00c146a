"""The body model: anny (default rig and topology) with an exact, fast keypoint path.

Shape is per person (6 phenotypes in [0, 1]); pose is per frame (one rotation per posed bone, in anny's
"local-ref" parameterization, plus the root translation). :meth:`BodyModel.rest_skeleton` does the per-person
work once per shape update; :meth:`BodyModel.keypoints` then runs a 22-bone forward kinematics and a small
contraction per frame, and equals anny's full forward + COCO regressor up to float round-off
(``docs/body_model.md``).
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import torch
from torch import Tensor

from humancal.body.bones import POSED_BONE_NAMES
from humancal.body.checks import check_finite, check_tensor, check_unit_interval
from humancal.body.kinematics import forward_kinematics, keypoints_from_bones
from humancal.body.reduction import build_reduction, rest_skeleton_from_coefficients
from humancal.body.rest import RestSkeleton
from humancal.keypoints import CANONICAL_JOINTS, NUM_JOINTS
from humancal.settings import anny_cache_dir

__all__ = ["BodyModel", "PHENOTYPE_NAMES"]

logger = logging.getLogger(__name__)

PHENOTYPE_NAMES: tuple[str, ...] = ("gender", "age", "muscle", "weight", "height", "proportions")
"""Columns of every phenotype tensor, each in [0, 1] (anny's default phenotype set, in anny's order).
gender 0 = male, 1 = female; age 0 = baby, 1/3 = child, 2/3 = young adult, 1 = old; the others span anny's
anchors from 0 (minimum) to 1 (maximum). anny's ranges are wide: a young adult male (gender 0, age 2/3, the
rest 0.5) is 1.91 m tall, and ``height`` moves that from 1.36 m (0) to 2.45 m (1); see ``docs/body_model.md``."""


def _use_cache_dir(cache_dir: Path) -> None:
    """Point anny at ``cache_dir`` (environment for subprocesses, anny's setter for this process)."""
    import anny.paths

    os.environ["ANNY_CACHE_DIR"] = str(cache_dir)
    anny.paths.set_anny_cache_path(cache_dir)
    if not any(cache_dir.glob("v*/build_compact_model_data_*.safetensors")):
        logger.warning(
            "no built anny model data in %s: anny builds it now (about 60 s and 1.5 GB of memory, once)", cache_dir
        )


class BodyModel:
    """anny wrapped for humancal: per-person rest skeleton, per-frame exact keypoints, full meshes on demand.

    Args:
        dtype: floating dtype of every tensor (float32 is about 2x faster than float64 in anny).
        device: torch device.
        cache_dir: anny's cache of built model data; default ``humancal.settings.anny_cache_dir()``.

    Attributes:
        posed_bones: names of the posed bones, root first, parents before children (``humancal.body.bones``).
        posed_parents: parent of each posed bone (index into ``posed_bones``, -1 for the root).
        faces: (F_tri, 3) int64 triangle vertex indices of the mesh.
        num_vertices: V, the number of mesh vertices (13718).
        keypoint_names: the 23 canonical keypoints (``humancal.keypoints.CANONICAL_JOINTS``).
        anny_model: the wrapped ``anny.Anny`` module (for mesh-level work; treat as read-only).
    """

    def __init__(
        self,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str = "cpu",
        cache_dir: str | Path | None = None,
    ) -> None:
        if dtype not in (torch.float32, torch.float64):
            raise ValueError(f"BodyModel dtype must be torch.float32 or torch.float64, got {dtype}")
        start = time.perf_counter()
        _use_cache_dir(Path(cache_dir) if cache_dir is not None else anny_cache_dir())
        import anny

        model = anny.Anny().to(dtype=dtype, device=device)
        model.requires_grad_(False)
        if list(model.phenotype_labels) != list(PHENOTYPE_NAMES):
            raise ValueError(f"anny phenotypes are {model.phenotype_labels}, humancal expects {list(PHENOTYPE_NAMES)}")
        if model.pose_parameterization != "local-ref" or model.bone_orientation != "cached":
            raise ValueError(
                "humancal.body expects anny's default 'local-ref' pose parameterization and cached bone orientations, "
                f"got {model.pose_parameterization!r} / {model.bone_orientation!r}"
            )
        if model.rest_orientation_refiner is not None:
            raise ValueError("humancal.body does not support anny rigs with a rest-orientation refiner")
        regressor = anny.KeypointsRegressor.coco(model)
        if list(regressor.labels) != list(CANONICAL_JOINTS):
            raise ValueError(f"anny COCO regressor labels {regressor.labels} differ from the canonical 23 keypoints")
        self.anny_model = model
        self.keypoint_regressor = regressor
        self._reduction = build_reduction(model, regressor.regression_weights)
        self.dtype = dtype
        self.device = torch.device(device)
        self.posed_bones: tuple[str, ...] = POSED_BONE_NAMES
        self.posed_parents: tuple[int, ...] = self._reduction.posed_parents
        self.faces: Tensor = model.faces.to(device=self.device, dtype=torch.int64)
        self.num_vertices: int = int(model.template_vertices.shape[0])
        self.keypoint_names: tuple[str, ...] = CANONICAL_JOINTS
        logger.info("BodyModel ready in %.2f s (%s, %s)", time.perf_counter() - start, dtype, self.device)

    # ------------------------------------------------------------------ validation

    @property
    def num_posed_bones(self) -> int:
        """B, the number of posed bones."""
        return len(self.posed_bones)

    def _check_phenotypes(self, phenotypes: Tensor) -> Tensor:
        check_tensor(phenotypes, "phenotypes", ("P", len(PHENOTYPE_NAMES)), "people x " + ", ".join(PHENOTYPE_NAMES))
        check_finite(phenotypes, "phenotypes")
        check_unit_interval(phenotypes, "phenotypes", PHENOTYPE_NAMES)
        return self._check_dtype(phenotypes, "phenotypes")

    def _check_dtype(self, value: Tensor, name: str) -> Tensor:
        if value.dtype != self.dtype or value.device.type != self.device.type:
            raise ValueError(
                f"{name} must be {self.dtype} on {self.device} like the BodyModel, got {value.dtype} on {value.device}"
            )
        return value

    def _check_pose(self, bone_rotmats_local: Tensor, root_translation_m: Tensor, num_people: int | None) -> None:
        people: str | int = "P" if num_people is None else num_people
        check_tensor(
            bone_rotmats_local, "bone_rotmats_local", (people, "F", self.num_posed_bones, 3, 3),
            f"people x frames x {self.num_posed_bones} posed bones x rotation matrix",
        )
        p, f = bone_rotmats_local.shape[:2]
        check_tensor(root_translation_m, "root_translation_m", (p, f, 3), "people x frames x xyz metres")
        check_finite(bone_rotmats_local, "bone_rotmats_local")
        check_finite(root_translation_m, "root_translation_m")
        self._check_dtype(bone_rotmats_local, "bone_rotmats_local")
        self._check_dtype(root_translation_m, "root_translation_m")

    # ------------------------------------------------------------------ shape

    def blendshape_coefficients(self, phenotypes: Tensor) -> Tensor:
        """anny's phenotype blendshape coefficients.

        Args:
            phenotypes: (P, 6) in [0, 1], columns ``PHENOTYPE_NAMES``.

        Returns:
            (P, C) coefficients of anny's (compacted) blendshape basis.
        """
        self._check_phenotypes(phenotypes)
        empty = phenotypes.new_zeros(phenotypes.shape[0], 0)
        return self.anny_model._get_phenotype_blendshape_coefficients(phenotypes, empty, empty)

    def rest_skeleton(self, phenotypes: Tensor) -> RestSkeleton:
        """Everything the per-frame keypoint path needs for these people (call once per shape update).

        Args:
            phenotypes: (P, 6) in [0, 1], columns ``PHENOTYPE_NAMES``.

        Returns:
            The :class:`RestSkeleton`, differentiable w.r.t. ``phenotypes``.

        Raises:
            ValueError: wrong shape, dtype or device, non-finite values, or values outside [0, 1].
        """
        coefficients = self.blendshape_coefficients(phenotypes)
        return rest_skeleton_from_coefficients(self.anny_model, self._reduction, phenotypes, coefficients)

    def rest_vertices(self, phenotypes: Tensor) -> Tensor:
        """(P, V, 3) rest mesh (before any pose; anny's own rest frame), metres, Z up."""
        return self.anny_model.get_rest_vertices(self.blendshape_coefficients(phenotypes))

    def height_m(self, phenotypes: Tensor) -> Tensor:
        """Standing height: top of the head to the lowest sole vertex of the rest mesh.

        Args:
            phenotypes: (P, 6) in [0, 1].

        Returns:
            (P,) heights, metres (differentiable).
        """
        z = self.rest_vertices(phenotypes)[..., 2]
        return z.amax(dim=-1) - z.amin(dim=-1)

    def root_height_m(self, phenotypes: Tensor) -> Tensor:
        """Height of the root bone head above the lowest vertex in the identity pose.

        Setting ``root_translation_m[..., 2]`` to this value (identity pose) puts the soles on the floor z = 0.

        Args:
            phenotypes: (P, 6) in [0, 1].

        Returns:
            (P,) metres (differentiable).
        """
        num_people = int(self._check_phenotypes(phenotypes).shape[0])
        identity = self.identity_pose(num_people, 1)
        translation = torch.zeros(num_people, 1, 3, dtype=self.dtype, device=self.device)
        vertices = self.reference_forward(phenotypes, identity, translation)["vertices"]
        return -vertices[:, 0, :, 2].amin(dim=-1)

    # ------------------------------------------------------------------ pose

    def identity_pose(self, num_people: int, num_frames: int) -> Tensor:
        """(P, F, B, 3, 3) identity rotations (the reference pose: upright, facing -y, arms in anny's rest pose)."""
        eye = torch.eye(3, dtype=self.dtype, device=self.device)
        return eye.expand(num_people, num_frames, self.num_posed_bones, 3, 3).clone()

    def _forward_kinematics(
        self, rest: RestSkeleton, bone_rotmats_local: Tensor, root_translation_m: Tensor
    ) -> tuple[Tensor, Tensor]:
        if not isinstance(rest, RestSkeleton):
            raise ValueError(f"rest must be a RestSkeleton from BodyModel.rest_skeleton, got {type(rest).__name__}")
        self._check_pose(bone_rotmats_local, root_translation_m, rest.num_people)
        return forward_kinematics(bone_rotmats_local, root_translation_m, rest.chain_offsets_m, self._reduction.chain)

    def keypoints(self, rest: RestSkeleton, bone_rotmats_local: Tensor, root_translation_m: Tensor) -> Tensor:
        """The 23 canonical keypoints, exactly anny's skinned mesh + COCO regressor, without the mesh.

        Args:
            rest: :meth:`rest_skeleton` of the P people.
            bone_rotmats_local: (P, F, B, 3, 3) rotation of each posed bone in anny's "local-ref"
                parameterization (world-aligned axes about the bone's head, composed child after parent);
                bone 0 (root) is the body's global orientation.
            root_translation_m: (P, F, 3) world position of the root bone head, metres.

        Returns:
            (P, F, 23, 3) keypoints in world metres, Z up, order ``humancal.keypoints.CANONICAL_JOINTS``.

        Raises:
            ValueError: wrong shapes (naming the argument and the expected shape), non-finite values, a dtype or
                device other than the model's.
        """
        rotations, heads = self._forward_kinematics(rest, bone_rotmats_local, root_translation_m)
        return keypoints_from_bones(rotations, heads, rest.keypoint_linear_m, rest.keypoint_affine)

    def joints(self, rest: RestSkeleton, bone_rotmats_local: Tensor, root_translation_m: Tensor) -> Tensor:
        """World positions of the posed bones' heads.

        Args and Raises: as :meth:`keypoints`.

        Returns:
            (P, F, B, 3) metres; ``toes.*`` report the head of the big toe's proximal bone.
        """
        return self._forward_kinematics(rest, bone_rotmats_local, root_translation_m)[1]

    def bone_world_rotations(self, rest: RestSkeleton, bone_rotmats_local: Tensor, root_translation_m: Tensor) -> Tensor:
        """World rotation of each posed bone relative to the reference pose (what turns a bone-fixed offset).

        Args and Raises: as :meth:`keypoints`.

        Returns:
            (P, F, B, 3, 3).
        """
        return self._forward_kinematics(rest, bone_rotmats_local, root_translation_m)[0]

    def keypoints_and_joints(
        self, rest: RestSkeleton, bone_rotmats_local: Tensor, root_translation_m: Tensor
    ) -> tuple[Tensor, Tensor]:
        """:meth:`keypoints` and :meth:`joints` from one forward kinematics: (P, F, 23, 3), (P, F, B, 3)."""
        rotations, heads = self._forward_kinematics(rest, bone_rotmats_local, root_translation_m)
        return keypoints_from_bones(rotations, heads, rest.keypoint_linear_m, rest.keypoint_affine), heads

    # ------------------------------------------------------------------ reference

    def anny_pose_parameters(self, bone_rotmats_local: Tensor, root_translation_m: Tensor) -> Tensor:
        """anny's full (..., 104, 4, 4) "local-ref" delta transforms for a humancal pose.

        Args:
            bone_rotmats_local: (..., B, 3, 3) posed-bone rotations.
            root_translation_m: (..., 3) root head positions, metres.

        Returns:
            (..., 104, 4, 4); bones outside the posed set are identity, ``toes.*`` fill their five toe bones.
        """
        batch = bone_rotmats_local.shape[:-3]
        num_bones = len(self.anny_model.bone_labels)
        rotations = torch.eye(3, dtype=bone_rotmats_local.dtype, device=bone_rotmats_local.device)
        rotations = rotations.expand(*batch, num_bones, 3, 3).clone()
        reduction = self._reduction
        rotations[..., reduction.articulated_bones, :, :] = bone_rotmats_local[..., reduction.pose_index, :, :]
        translations = root_translation_m.new_zeros(*batch, num_bones, 3)
        translations[..., 0, :] = root_translation_m
        top = torch.cat([rotations, translations[..., None]], dim=-1)
        bottom = torch.zeros_like(top[..., :1, :])
        bottom[..., 0, 3] = 1.0
        return torch.cat([top, bottom], dim=-2)

    def reference_forward(
        self, phenotypes: Tensor, bone_rotmats_local: Tensor, root_translation_m: Tensor
    ) -> dict[str, Tensor]:
        """anny's own full forward (skinned mesh) and COCO regressor: the ground truth, and the mesh output.

        Args:
            phenotypes: (P, 6) in [0, 1].
            bone_rotmats_local: (P, F, B, 3, 3) as in :meth:`keypoints`.
            root_translation_m: (P, F, 3) metres.

        Returns:
            dict with ``keypoints`` (P, F, 23, 3), ``joints`` (P, F, B, 3) and ``vertices`` (P, F, V, 3), world
            metres; differentiable. Memory grows as P x F x 13,718 vertices (about 0.16 MB per person-frame
            in float32, several times that with gradients): call it on chunks of frames for long sequences.

        Raises:
            ValueError: as :meth:`keypoints` and :meth:`rest_skeleton`.
        """
        self._check_phenotypes(phenotypes)
        self._check_pose(bone_rotmats_local, root_translation_m, int(phenotypes.shape[0]))
        pose = self.anny_pose_parameters(bone_rotmats_local, root_translation_m)
        joint_bones = self._reduction.joint_bones
        keypoints, joints, vertices = [], [], []
        # One anny call per person: the rest mesh is computed once and shared by the frames.
        for person in range(phenotypes.shape[0]):
            output = self.anny_model(pose_parameters=pose[person], phenotype_kwargs=phenotypes[person : person + 1])
            keypoints.append(self.keypoint_regressor(output))
            joints.append(output["bone_poses"][:, joint_bones, :3, 3])
            vertices.append(output["vertices"])
        return {
            "keypoints": torch.stack(keypoints),
            "joints": torch.stack(joints),
            "vertices": torch.stack(vertices),
        }

    def __repr__(self) -> str:
        return (
            f"BodyModel(anny, {self.num_posed_bones} posed bones, {NUM_JOINTS} keypoints, "
            f"{self.num_vertices} vertices, {self.dtype}, {self.device})"
        )
