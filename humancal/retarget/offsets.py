"""Poses of many frames and the shared correspondence offsets, solved together (Gauss-Newton, Schur complement).

Why together: at a chain end whose points all have free offsets (the head with the eyes, the hand with the
knuckles, the foot with the toe tip), rotating the bone by any ``Q`` and its offsets by ``Q^T`` leaves the data
term unchanged (a *gauge*): only the priors decide that rotation. Alternating pose fits and offset fits cannot
move along a gauge (each block alone sees it as fixed), so whatever rotation the start had would stay; a joint
second-order step follows the priors along it. (Offsets inside the chain are lengths along a segment,
``"along"`` in :mod:`humancal.retarget.correspondence`, precisely so that they open no gauge there.)

The unknowns are the per-frame pose increments (as in :mod:`humancal.retarget.levenberg`) and the coordinates
``phi`` of the offsets in :meth:`PointModel.offset_basis`, ``offsets = basis @ phi``. The normal equations have
the arrow shape of bundle adjustment; the frames are eliminated (Schur complement) and one small system in
``phi`` is solved per iteration. The frames need not be consecutive (no smoothness term).
"""

from __future__ import annotations

import logging

import roma
import torch
from torch import Tensor

from humancal.body import RestSkeleton
from humancal.retarget.levenberg import PointStructure, frame_costs
from humancal.retarget.priors import PoseWeights
from humancal.retarget.points import PointModel

__all__ = ["fit_poses_and_offsets"]

logger = logging.getLogger(__name__)


def _total_cost(points, rest, basis, phi, rotmats, translation, targets_m, weights, prior_weight):
    """Objective, coefficients and structure for offsets ``basis @ phi`` (float64 throughout)."""
    coefficients = points.coefficients(rest, (basis @ phi).reshape(-1, 3))
    structure = PointStructure(coefficients, points.subtree)
    cost = frame_costs(points, coefficients, structure, rotmats, translation, targets_m, weights, None)
    return cost.sum() + targets_m.shape[0] * (prior_weight * phi**2).sum(), coefficients, structure


def fit_poses_and_offsets(
    points: PointModel,
    rest: RestSkeleton,
    rotmats: Tensor,
    translation: Tensor,
    coordinates: Tensor,
    targets_m: Tensor,
    pose_weights: PoseWeights,
    offset_prior_weights: Tensor,
    iterations: int,
) -> tuple[Tensor, Tensor, Tensor, float]:
    """Levenberg-Marquardt over the poses of F frames and the shared offsets (shape fixed), in float64.

    Objective: ``sum_f cost_f + F * sum_j offset_prior_weights_j * phi_j^2`` with ``cost_f`` the pose objective of
    frame f without smoothness (:func:`humancal.retarget.levenberg.frame_costs`), i.e. ``F`` times the mean-over-
    frames objective of :func:`humancal.retarget.pose.pose_objective` plus the offset prior.

    Args:
        points: the mapped-point model.
        rest: the person's rest skeleton (fixed).
        rotmats: (F, B, 3, 3) starting local-ref rotations.
        translation: (F, 3) starting root translations, metres.
        coordinates: (k,) starting offset coordinates in ``points.offset_basis(rest)``, metres.
        targets_m: (F, M, 3) mocap positions, metres.
        pose_weights: the pose, hinge and pelvis-tilt priors (:meth:`PoseWeights.from_config`; smoothness is not
            used).
        offset_prior_weights: (k,) prior weight per offset coordinate (:meth:`PointModel.offset_prior_weights`).
        iterations: the most iterations.

    Returns:
        rotmats (F, B, 3, 3), translation (F, 3), offset coordinates (k,), all float64, and the final objective
        (m^2).
    """
    f64 = torch.float64
    weights = PoseWeights(pose_weights.bone_prior, 0.0, pose_weights.hinge_bones, pose_weights.hinge_axes,
                          pose_weights.hinge_directions, pose_weights.hinge, pose_weights.pelvis_tilt)
    with torch.no_grad():
        basis = points.offset_basis(rest, f64)
    rotmats, translation, targets_m = rotmats.to(f64), translation.to(f64), targets_m.to(f64)
    phi = coordinates.to(f64)
    num_frames, num_bones = rotmats.shape[:2]
    num_points, k = points.num_points, basis.shape[1]
    carrier = points.carrier
    basis_per_point = basis.reshape(num_points, 3, k)
    root_weight = points.weight.to(f64).sqrt()
    frame_prior = num_frames * offset_prior_weights.to(f64)
    damping = 1e-3
    total, coefficients, structure = _total_cost(
        points, rest, basis, phi, rotmats, translation, targets_m, weights, offset_prior_weights
    )
    for _ in range(iterations):
        _, rotations, g_x, h_xx, jac_x, residual = frame_costs(
            points, coefficients, structure, rotmats, translation, targets_m, weights, None,
            derivatives=True, jacobian=True,
        )
        # d p_m / d phi = G_carrier(m) @ basis_m, scaled like the residual rows.
        jac_phi = torch.einsum("fmij,mjk->fmik", rotations[:, carrier], basis_per_point)
        jac_phi = (jac_phi * root_weight[None, :, None, None]).reshape(num_frames, 3 * num_points, k)
        h_xphi = jac_x.transpose(1, 2) @ jac_phi  # (F, N, k)
        h_phiphi = torch.einsum("fri,frj->ij", jac_phi, jac_phi) + torch.diag(frame_prior)
        g_phi = torch.einsum("fri,fr->i", jac_phi, residual) + frame_prior * phi
        while True:
            damped_xx = h_xx.clone()
            torch.diagonal(damped_xx, dim1=-2, dim2=-1).mul_(1.0 + damping).add_(1e-12)
            damped_pp = h_phiphi.clone()
            torch.diagonal(damped_pp).mul_(1.0 + damping).add_(1e-12)
            factor = torch.linalg.cholesky(damped_xx)
            solved = torch.cholesky_solve(torch.cat([g_x[..., None], h_xphi], dim=2), factor)  # H_xx^-1 [g | H_xphi]
            schur = damped_pp - torch.einsum("fni,fnj->ij", h_xphi, solved[..., 1:])
            rhs = g_phi - torch.einsum("fni,fn->i", h_xphi, solved[..., 0])
            step_phi = -torch.linalg.solve(schur, rhs)
            step_x = -(solved[..., 0] + (solved[..., 1:] @ step_phi))
            new_translation = translation + step_x[:, :3]
            world_step = step_x[:, 3:].reshape(num_frames, num_bones, 3)
            local_step = (rotations.transpose(-1, -2) @ world_step[..., None])[..., 0]
            new_rotmats = rotmats @ roma.rotvec_to_rotmat(local_step)
            new_phi = phi + step_phi
            new_total, new_coefficients, new_structure = _total_cost(
                points, rest, basis, new_phi, new_rotmats, new_translation, targets_m, weights, offset_prior_weights
            )
            if new_total < total or damping > 1e6:
                break
            damping *= 4.0
        if not new_total < total:
            break
        gain = float(total - new_total)
        rotmats, translation, phi = new_rotmats, new_translation, new_phi
        total, coefficients, structure = new_total, new_coefficients, new_structure
        damping = max(damping / 3.0, 1e-7)
        if gain <= 1e-10 * float(total) + 1e-14:
            break
    return rotmats, translation, phi, float(total)
