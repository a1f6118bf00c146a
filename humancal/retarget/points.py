"""The mapped points of the body model: the anny side of the joint correspondence, as torch functions.

For one person: ``p_m = anchor_m + G_carrier(m) @ offset_m`` (see :mod:`humancal.retarget.correspondence`).
Every anchor of the exact fast path (``docs/body_model.md``) is linear in the posed bones' world transforms, and
so is the offset term, so all mapped points share one form::

    p_m = sum_b ( G_b @ linear_m[b] + affine_m[b] * w_b )

with ``G_b`` the world rotation of posed bone ``b`` relative to the reference pose and ``w_b`` its world head.
A bone-head anchor is ``affine = one-hot``; a keypoint takes its row of the rest skeleton's keypoint map; an
offset adds to ``linear`` at the carrier. The same coefficients give the Jacobians of the Gauss-Newton pose fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from humancal.body import BodyModel, RestSkeleton
from humancal.body.kinematics import chain_levels, forward_kinematics
from humancal.retarget.correspondence import ResolvedLinks

__all__ = ["PointModel", "PointCoefficients"]

@dataclass(frozen=True)
class PointCoefficients:
    """The mapped points of one person as a linear function of the bones' world transforms.

    Attributes:
        linear_m: (M, B, 3) the part of point ``m`` that rotates with bone ``b``, metres.
        affine: (M, B) the weight of bone ``b``'s head in point ``m`` (each row sums to 1).
        chain_offsets_m: (1, B, 3) the rest skeleton's chain offsets (for the forward kinematics), metres.
    """

    linear_m: Tensor
    affine: Tensor
    chain_offsets_m: Tensor

    def to(self, dtype: torch.dtype) -> "PointCoefficients":
        """The same coefficients in another dtype."""
        return PointCoefficients(self.linear_m.to(dtype), self.affine.to(dtype), self.chain_offsets_m.to(dtype))


class PointModel:
    """Evaluates the M mapped points of a correspondence table on the body model (one person at a time).

    Args:
        body: the body model (its dtype and device are used throughout).
        resolved: the correspondence resolved against ``body`` (:func:`resolve_links`).
    """

    def __init__(self, body: BodyModel, resolved: ResolvedLinks) -> None:
        self.body = body
        self.resolved = resolved
        self.parents = tuple(body.posed_parents)
        self.chain = chain_levels(self.parents).to(body.device)
        num_bones = len(self.parents)
        options = {"device": body.device}
        self.is_keypoint = resolved.anchor_bone < 0
        self.keypoint_rows = torch.as_tensor(np.flatnonzero(self.is_keypoint), **options)
        self.keypoint_index = torch.as_tensor(resolved.anchor_keypoint[self.is_keypoint], **options)
        bone_affine = np.zeros((resolved.num_points, num_bones))
        rows = np.flatnonzero(~self.is_keypoint)
        bone_affine[rows, resolved.anchor_bone[rows]] = 1.0
        self.bone_affine = torch.as_tensor(bone_affine, dtype=body.dtype, **options)
        carrier_onehot = np.zeros((resolved.num_points, num_bones))
        carrier_onehot[np.arange(resolved.num_points), resolved.carrier] = 1.0
        self.carrier_onehot = torch.as_tensor(carrier_onehot, dtype=body.dtype, **options)
        self.carrier = torch.as_tensor(resolved.carrier, **options)
        self.weight = torch.as_tensor(resolved.weight, dtype=body.dtype, **options)
        subtree = np.eye(num_bones)
        for b in range(num_bones - 1, 0, -1):  # parents come before children: accumulate bottom-up
            subtree[self.parents[b]] += subtree[b]
        self.subtree = torch.as_tensor(subtree > 0, dtype=body.dtype, **options)
        """(B, B) ``subtree[b, e] = 1`` when bone ``e`` is ``b`` or one of its descendants."""

    @property
    def num_points(self) -> int:
        """M, the number of mapped points."""
        return self.resolved.num_points

    def offset_column_kinds(self) -> tuple[str, ...]:
        """The offset kind (``"along"`` or ``"free"``) of each column of :meth:`offset_basis`, in order."""
        kinds: list[str] = []
        for m, kind in enumerate(self.resolved.offset_kind):
            twin = int(self.resolved.mirror[m])
            if kind == "none" or twin < m:
                continue
            kinds += [kind] if kind == "along" else [kind] * (2 if twin == m else 3)
        return tuple(kinds)

    def offset_prior_weights(
        self, along_weight: float, free_weight: float, dtype: torch.dtype = torch.float64
    ) -> Tensor:
        """(k,) prior weight of each offset coordinate (``along_weight`` or ``free_weight`` by its kind)."""
        weights = [along_weight if kind == "along" else free_weight for kind in self.offset_column_kinds()]
        return torch.tensor(weights, dtype=dtype, device=self.body.device)

    def offset_basis(self, rest: RestSkeleton, dtype: torch.dtype = torch.float64) -> Tensor:
        """Orthonormal basis of the learnable offsets: ``offsets_m = (basis @ coordinates).reshape(M, 3)``.

        An ``"along"`` point gives its unit segment direction (carrier head -> anchor in the reference pose),
        shared by a mirror pair as ``(d_L, d_R) / sqrt 2``; a ``"free"`` midline point its y and z axes; a
        ``"free"`` pair ``(e_x, -e_x) / sqrt 2``, ``(e_y, e_y) / sqrt 2``, ``(e_z, e_z) / sqrt 2``. The directions
        depend on the shape, so the basis is differentiable w.r.t. ``rest``.

        Args:
            rest: rest skeleton of one person.
            dtype: dtype of the basis.

        Returns:
            (3 M, k) basis, k the number of offset degrees of freedom.
        """
        resolved = self.resolved
        num_points = resolved.num_points
        zero = torch.zeros(3, dtype=dtype, device=self.body.device)
        anchors = self.rest_points_m(self.coefficients(rest, zero.new_zeros(num_points, 3)))
        heads = rest.bone_heads_m[0].to(dtype)
        scale = 2.0**-0.5
        columns = []

        def column(entries: dict[int, Tensor]) -> Tensor:
            return torch.stack([entries.get(m, zero) for m in range(num_points)]).reshape(-1)

        def direction(m: int) -> Tensor:
            return torch.nn.functional.normalize(anchors[m] - heads[int(resolved.carrier[m])], dim=0)

        axes = torch.eye(3, dtype=dtype, device=self.body.device)
        for m, kind in enumerate(resolved.offset_kind):
            twin = int(resolved.mirror[m])
            if kind == "none" or twin < m:
                continue
            if kind == "along":
                columns.append(column({m: direction(m)} if twin == m else
                                      {m: scale * direction(m), twin: scale * direction(twin)}))
            elif twin == m:
                columns += [column({m: axes[1]}), column({m: axes[2]})]
            else:
                columns += [column({m: scale * axes[0], twin: -scale * axes[0]}),
                            column({m: scale * axes[1], twin: scale * axes[1]}),
                            column({m: scale * axes[2], twin: scale * axes[2]})]
        if not columns:
            return torch.zeros(3 * num_points, 0, dtype=dtype, device=self.body.device)
        return torch.stack(columns, dim=1)

    def coefficients(self, rest: RestSkeleton, offsets_m: Tensor) -> PointCoefficients:
        """The linear form of the mapped points for one person (differentiable w.r.t. rest and offsets).

        Args:
            rest: rest skeleton of one person (P = 1).
            offsets_m: (M, 3) offsets (:meth:`offset_basis` times coordinates), metres; their dtype is the
                coefficients' dtype.
        """
        dtype = offsets_m.dtype
        linear = self.carrier_onehot.to(dtype)[..., None] * offsets_m[:, None, :]
        affine = self.bone_affine.to(dtype)
        if len(self.keypoint_rows):
            keypoint_linear = torch.zeros_like(linear).index_copy(
                0, self.keypoint_rows, rest.keypoint_linear_m[0, self.keypoint_index].to(dtype)
            )
            keypoint_affine = torch.zeros_like(affine).index_copy(
                0, self.keypoint_rows, rest.keypoint_affine[0, self.keypoint_index].to(dtype)
            )
            linear = linear + keypoint_linear
            affine = affine + keypoint_affine
        return PointCoefficients(linear, affine, rest.chain_offsets_m.to(dtype))

    def world_transforms(
        self, coefficients: PointCoefficients, bone_rotmats_local: Tensor, root_translation_m: Tensor
    ) -> tuple[Tensor, Tensor]:
        """World rotations ``G_b`` (F, B, 3, 3) and heads ``w_b`` (F, B, 3) of the posed bones.

        Args:
            coefficients: from :meth:`coefficients`.
            bone_rotmats_local: (F, B, 3, 3) local-ref rotations.
            root_translation_m: (F, 3) root head positions, metres.
        """
        rotations, heads = forward_kinematics(
            bone_rotmats_local[None], root_translation_m[None], coefficients.chain_offsets_m, self.chain
        )
        return rotations[0], heads[0]

    @staticmethod
    def points_from_transforms(coefficients: PointCoefficients, rotations: Tensor, heads_m: Tensor) -> Tensor:
        """(F, M, 3) mapped points from world rotations (F, B, 3, 3) and heads (F, B, 3), metres."""
        return torch.einsum("fbij,mbj->fmi", rotations, coefficients.linear_m) + torch.einsum(
            "mb,fbi->fmi", coefficients.affine, heads_m
        )

    def points(
        self, coefficients: PointCoefficients, bone_rotmats_local: Tensor, root_translation_m: Tensor
    ) -> Tensor:
        """World positions of the mapped points.

        Args:
            coefficients: from :meth:`coefficients`.
            bone_rotmats_local: (F, B, 3, 3) local-ref bone rotations.
            root_translation_m: (F, 3) root head positions, metres.

        Returns:
            (F, M, 3) world positions, metres.
        """
        rotations, heads = self.world_transforms(coefficients, bone_rotmats_local, root_translation_m)
        return self.points_from_transforms(coefficients, rotations, heads)

    def rest_heads_m(self, coefficients: PointCoefficients) -> Tensor:
        """(B, 3) the posed bones' heads in the reference pose (root head at the origin)."""
        num_bones = len(self.parents)
        eye = torch.eye(3, dtype=coefficients.linear_m.dtype, device=coefficients.linear_m.device)
        return self.world_transforms(coefficients, eye.expand(1, num_bones, 3, 3), eye.new_zeros(1, 3))[1][0]

    def rest_points_m(self, coefficients: PointCoefficients) -> Tensor:
        """(M, 3) the mapped points in the reference pose (every rotation identity, root head at the origin)."""
        num_bones = len(self.parents)
        eye = torch.eye(3, dtype=coefficients.linear_m.dtype, device=coefficients.linear_m.device)
        identity = eye.expand(1, num_bones, 3, 3)
        zero = coefficients.linear_m.new_zeros(1, 3)
        return self.points(coefficients, identity, zero)[0]
