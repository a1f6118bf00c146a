"""The regularisers of the pose fit: pose prior, hinge prior for knees and elbows, pelvis tilt, smoothness.

Their weights live in ``RetargetConfig``; :class:`PoseWeights` holds them for one person (the hinge axes depend
on the rest skeleton). The costs are evaluated (and differentiated) in :mod:`humancal.retarget.levenberg` and
:func:`humancal.retarget.pose.pose_objective`.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from humancal.retarget.points import PointCoefficients, PointModel

__all__ = ["PoseWeights"]


class PoseWeights:
    """The regulariser weights of the pose objective (see ``RetargetConfig``).

    Args:
        bone_prior: (B,) weight of ``|D_b - I|_F^2`` per posed bone (0 for the root).
        smooth: weight of the frame-to-frame differences.
        hinge_bones: (H,) posed-bone indices of hinge joints (knees, elbows).
        hinge_axes: (H, 3) unit flexion axis ``a`` of each, reference-pose axes.
        hinge_directions: (H, 3) unit rest direction ``d`` of each hinge bone (its head to its child's head).
        hinge: weight of ``(a . D d)^2``: how far the bone leaves the plane of its flexion (bending sideways);
            flexion about ``a`` and twist about ``d`` are free.
        pelvis_tilt: weight of ``|u - e_z|^2 = 2 (1 - cos tilt)``, ``u`` the pelvis' up axis in the world.
    """

    def __init__(
        self,
        bone_prior: Tensor,
        smooth: float,
        hinge_bones: Tensor | None = None,
        hinge_axes: Tensor | None = None,
        hinge_directions: Tensor | None = None,
        hinge: float = 0.0,
        pelvis_tilt: float = 0.0,
    ) -> None:
        self.bone_prior = bone_prior
        self.smooth = float(smooth)
        self.hinge_bones = hinge_bones if hinge_bones is not None else torch.zeros(0, dtype=torch.long)
        self.hinge_axes = hinge_axes if hinge_axes is not None else torch.zeros(0, 3, dtype=torch.float64)
        self.hinge_directions = hinge_directions if hinge_directions is not None else self.hinge_axes.clone()
        self.hinge = float(hinge)
        self.pelvis_tilt = float(pelvis_tilt)

    @classmethod
    def from_config(
        cls, config, points: PointModel, coefficients: PointCoefficients, smooth: bool = True, shape_fit: bool = False
    ) -> "PoseWeights":
        """The weights of ``config`` for one person: ``pose_prior_weight`` times ``bone_prior_scale`` per bone
        (root 0), ``smooth_weight`` (unless ``smooth`` is false), the hinge prior with each hinge's axis from the
        person's rest skeleton (``coefficients``), and in the shape fit (``shape_fit``) the pelvis-tilt prior.

        A hinge's axis is the normal of the plane of its parent bone and itself in the reference pose (anny's
        elbows are bent 42 deg there), or the body's left-right axis x where that bend is under 10 deg (anny's
        nearly straight knees, which flex about +x, ``docs/body_model.md``).

        Raises:
            ValueError: ``bone_prior_scale`` or ``hinge_bones`` names a bone that is not posed, or a hinge bone
                has no child.
        """
        posed_bones, posed_parents = points.body.posed_bones, points.parents
        scale = dict(config.bone_prior_scale)
        unknown = sorted((set(scale) | set(config.hinge_bones)) - set(posed_bones))
        if unknown:
            raise ValueError(f"RetargetConfig names unknown bones {unknown}; posed bones: {list(posed_bones)}")
        prior = [
            0.0 if b == 0 else config.pose_prior_weight * scale.get(name, 1.0) for b, name in enumerate(posed_bones)
        ]
        heads = points.rest_heads_m(coefficients).detach().to(torch.float64)
        bones, axes, directions = [], [], []
        for name in config.hinge_bones:
            b = posed_bones.index(name)
            children = [c for c, p in enumerate(posed_parents) if p == b]
            if not children:
                raise ValueError(f"RetargetConfig.hinge_bones: {name!r} has no child bone to define its axis")
            upper, lower = heads[b] - heads[posed_parents[b]], heads[children[0]] - heads[b]
            normal = torch.linalg.cross(upper, lower)
            if normal.norm() < upper.norm() * lower.norm() * math.sin(math.radians(10.0)):
                normal = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
            axis = torch.nn.functional.normalize(normal, dim=0)
            direction = torch.nn.functional.normalize(lower, dim=0)
            bones.append(b)
            axes.append(axis)
            directions.append(torch.nn.functional.normalize(direction - (direction @ axis) * axis, dim=0))
        return cls(
            torch.tensor(prior, dtype=torch.float64),
            config.smooth_weight if smooth else 0.0,
            torch.tensor(bones, dtype=torch.long),
            torch.stack(axes) if axes else None,
            torch.stack(directions) if directions else None,
            config.hinge_prior_weight,
            config.pelvis_tilt_prior_weight if shape_fit else 0.0,
        )

    def hinge_residual(self, rotmats: Tensor) -> Tensor:
        """(F, H) ``a_h . (D_h d_h)`` for local-ref rotations (F, B, 3, 3): 0 while the hinge stays in its plane."""
        axes = self.hinge_axes.to(rotmats.dtype)
        directions = self.hinge_directions.to(rotmats.dtype)
        return ((rotmats[:, self.hinge_bones] @ directions[..., None])[..., 0] * axes).sum(-1)

    def pelvis_tilt_cost(self, rotmats: Tensor) -> Tensor:
        """(F,) ``pelvis_tilt * |u - e_z|^2`` with ``u = D_root e_z`` (the root's rotation is its world one)."""
        return self.pelvis_tilt * 2.0 * (1.0 - rotmats[:, 0, 2, 2])

    def hinge_cost(self, rotmats: Tensor) -> Tensor:
        """(F,) ``hinge * sum_h (a_h . D_h d_h)^2``."""
        if len(self.hinge_bones) == 0 or self.hinge == 0:
            return rotmats.new_zeros(rotmats.shape[0])
        return self.hinge * (self.hinge_residual(rotmats) ** 2).sum(-1)
