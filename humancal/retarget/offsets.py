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
``phi`` is solved per iteration (the library's Levenberg-Marquardt, :mod:`humancal.least_squares`). The frames
need not be consecutive (no smoothness term).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import roma
import torch
from torch import Tensor

from humancal.body import RestSkeleton
from humancal.least_squares import ArrowSystem, Damping, Stop, levenberg_marquardt, solve_damped
from humancal.retarget.levenberg import PointStructure, frame_costs
from humancal.retarget.priors import PoseWeights
from humancal.retarget.points import PointModel

__all__ = ["fit_poses_and_offsets"]

logger = logging.getLogger(__name__)

_DAMPING = Damping(start=1e-3, grow=4.0, shrink=3.0, floor=1e-7, ceiling=1e7, attempts=16)
"""Refused steps grow the damping fourfold, up to about 1e6 times the diagonal (sixteen tries) before it stops."""


def _total_cost(points, rest, basis, phi, rotmats, translation, targets_m, weights, prior_weight):
    """Objective, coefficients and structure for offsets ``basis @ phi`` (float64 throughout)."""
    coefficients = points.coefficients(rest, (basis @ phi).reshape(-1, 3))
    structure = PointStructure(coefficients, points.subtree)
    cost = frame_costs(points, coefficients, structure, rotmats, translation, targets_m, weights, None)
    return cost.sum() + targets_m.shape[0] * (prior_weight * phi**2).sum(), coefficients, structure


@dataclass(frozen=True)
class _JointProblem:
    """The fixed data of the joint fit (float64), with its linearisation and trial step for the LM driver.

    Attributes:
        points: the mapped-point model.
        rest: the person's rest skeleton.
        basis: (3 M, k) ``points.offset_basis(rest)``.
        targets_m: (F, M, 3) mocap positions, metres.
        weights: the pose priors, smoothness off.
        offset_prior_weights: (k,) prior weight per offset coordinate.
    """

    points: PointModel
    rest: RestSkeleton
    basis: Tensor
    targets_m: Tensor
    weights: PoseWeights
    offset_prior_weights: Tensor

    def offset_jacobian(self, rotations: Tensor) -> Tensor:
        """(F, 3 M, k) ``d p_m / d phi = G_carrier(m) @ basis_m``, scaled like the residual rows."""
        num_frames, num_points, k = rotations.shape[0], self.points.num_points, self.basis.shape[1]
        basis_per_point = self.basis.reshape(num_points, 3, k)
        root_weight = self.points.weight.to(torch.float64).sqrt()
        jac_phi = torch.einsum("fmij,mjk->fmik", rotations[:, self.points.carrier], basis_per_point)
        return (jac_phi * root_weight[None, :, None, None]).reshape(num_frames, 3 * num_points, k)

    def linearize(self, state):
        """``((ArrowSystem, rotations (F, B, 3, 3)), objective)`` at ``state = (rotmats, translation, phi)``."""
        rotmats, translation, phi = state
        total, coefficients, structure = _total_cost(
            self.points, self.rest, self.basis, phi, rotmats, translation, self.targets_m, self.weights,
            self.offset_prior_weights,
        )
        _, rotations, g_x, h_xx, jac_x, residual = frame_costs(
            self.points, coefficients, structure, rotmats, translation, self.targets_m, self.weights, None,
            derivatives=True, jacobian=True,
        )
        jac_phi = self.offset_jacobian(rotations)
        frame_prior = rotmats.shape[0] * self.offset_prior_weights.to(torch.float64)
        system = ArrowSystem(
            global_hessian=torch.einsum("fri,frj->ij", jac_phi, jac_phi) + torch.diag(frame_prior),
            block_hessian=h_xx,
            cross=jac_x.transpose(1, 2) @ jac_phi,  # (F, N, k)
            global_gradient=torch.einsum("fri,fr->i", jac_phi, residual) + frame_prior * phi,
            block_gradient=g_x,
        )
        return (system, rotations), total

    def trial(self, state, linearization, damping):
        """The state after the damped step and its objective (``inf`` when a frame's system is singular)."""
        system, rotations = linearization
        rotmats, translation, phi = state
        step = solve_damped(system, damping)
        if not bool(step.solved.all()):
            return state, float("inf")
        world_step = step.block_step[:, 3:].reshape(rotmats.shape[0], rotmats.shape[1], 3)
        local_step = (rotations.transpose(-1, -2) @ world_step[..., None])[..., 0]
        new_state = (rotmats @ roma.rotvec_to_rotmat(local_step), translation + step.block_step[:, :3],
                     phi + step.global_step)
        total = _total_cost(self.points, self.rest, self.basis, new_state[2], *new_state[:2], self.targets_m,
                            self.weights, self.offset_prior_weights)[0]
        return new_state, total


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
    problem = _JointProblem(points, rest, basis, targets_m, weights, offset_prior_weights)
    outcome = levenberg_marquardt(problem.linearize, problem.trial, (rotmats, translation, coordinates.to(f64)),
                                  max_iterations=iterations, damping=_DAMPING,
                                  stop=Stop(relative=1e-10, absolute=1e-14), relinearize_last=False)
    rotmats, translation, phi = outcome.state
    return rotmats, translation, phi, float(outcome.cost)
