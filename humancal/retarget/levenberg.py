"""The per-frame pose fit: analytic Jacobians of the mapped points, solved frame by frame in parallel by the library's
batched Levenberg-Marquardt (:mod:`humancal.least_squares`).

Why not autograd + L-BFGS: the kinematic chain makes the problem badly conditioned (a root rotation moves every
point by up to a metre, a wrist rotation one point by centimetres). On CMU clips L-BFGS needed about 200
iterations per chunk to bring the median residual from 9 to 4.7 mm, i.e. tens of seconds per thousand frames;
Gauss-Newton reaches the same optimum in a handful of iterations.

Per frame the unknowns are a rotation increment ``omega_b`` per bone (``D_b <- D_b @ exp(omega_b)``) and the root
translation. Rotating bone ``b`` by ``omega_b`` turns everything below it about its head ``w_b`` by
``G_b @ omega_b``, so a mapped point ``p_m = sum_e A_me`` (:mod:`humancal.retarget.points`) moves by
``(G_b omega_b) x U_mb`` with ``U_mb = sum_{e below b} A_me - (sum_{e below b} affine_me) w_b``: the Jacobian
``-[U_mb]_x G_b``. The Frobenius penalties ``|D - I|^2`` and ``|D(t) - D(t-1)|^2`` have the Jacobian
``vec(D [e_i]_x)``, whose Gram matrix is ``2 I``; the hinge term ``(a . D d)^2`` and the pelvis-tilt term
``|D_root e_z - e_z|^2`` are written out where they are added. Frames are coupled only by the smoothness term; each
iteration solves every frame with its neighbours held at their current values (a Jacobi sweep), which suits a weak
coupling.
"""

from __future__ import annotations

from dataclasses import dataclass

import roma
import torch
from torch import Tensor

from humancal.least_squares import ArrowSystem, Damping, Stop, levenberg_marquardt, solve_damped
from humancal.retarget.points import PointCoefficients, PointModel
from humancal.retarget.priors import PoseWeights

__all__ = ["PointStructure", "levenberg_marquardt_poses", "frame_costs"]


def _skew(v: Tensor) -> Tensor:
    zero = torch.zeros_like(v[..., 0])
    x, y, z = v.unbind(-1)
    return torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).unflatten(-1, (3, 3))


def _vee_of_antisymmetric_part(k: Tensor) -> Tensor:
    """``(K21 - K12, K02 - K20, K10 - K01)``: the gradient ``<D [e_i]_x, X>`` with ``K = D^T X``."""
    return torch.stack([k[..., 2, 1] - k[..., 1, 2], k[..., 0, 2] - k[..., 2, 0], k[..., 1, 0] - k[..., 0, 1]], -1)


class _Neighbours:
    """Previous / next frame of every frame of a chunk (masks say whether one exists)."""

    def __init__(self, rotmats: Tensor, translation: Tensor, previous: tuple[Tensor, Tensor] | None) -> None:
        num_frames = rotmats.shape[0]
        first_rot = previous[0][None] if previous is not None else rotmats[:1]
        first_trans = previous[1][None] if previous is not None else translation[:1]
        self.prev_rot = torch.cat([first_rot, rotmats[:-1]])
        self.prev_trans = torch.cat([first_trans, translation[:-1]])
        self.next_rot = torch.cat([rotmats[1:], rotmats[-1:]])
        self.next_trans = torch.cat([translation[1:], translation[-1:]])
        self.prev_mask = torch.ones(num_frames, dtype=rotmats.dtype)
        self.next_mask = torch.ones(num_frames, dtype=rotmats.dtype)
        if previous is None:
            self.prev_mask[0] = 0.0
        self.next_mask[-1] = 0.0


class PointStructure:
    """The sparsity of the mapped points, for one person's coefficients.

    A point depends on 1-2 bones directly (its anchor's bone and its offset's carrier; a keypoint on the few bones
    that skin it) and on their ancestors, so working on the non-zero (point, bone) entries instead of dense
    (M, B) arrays makes the per-frame work several times smaller.

    Args:
        coefficients: the person's coefficients (:meth:`PointModel.coefficients`).
        subtree: (B, B) ``PointModel.subtree``.
    """

    def __init__(self, coefficients: PointCoefficients, subtree: Tensor) -> None:
        linear, affine = coefficients.linear_m, coefficients.affine
        dtype = linear.dtype
        self.num_points, self.num_bones = affine.shape
        nonzero = (affine != 0) | (linear != 0).any(dim=-1)
        self.entry_point, self.entry_bone = torch.nonzero(nonzero, as_tuple=True)
        self.entry_linear = linear[self.entry_point, self.entry_bone]  # (K, 3)
        self.entry_affine = affine[self.entry_point, self.entry_bone]  # (K,)
        self.entry_to_point = torch.nn.functional.one_hot(self.entry_point, self.num_points).to(dtype)  # (K, M)
        inside = subtree.to(torch.bool)
        depends = (nonzero.to(dtype) @ subtree.to(dtype).T) > 0  # (M, B): some entry of m lies below b
        self.pair_point, self.pair_bone = torch.nonzero(depends, as_tuple=True)
        same_point = self.pair_point[:, None] == self.entry_point[None, :]
        below = inside[self.pair_bone[:, None], self.entry_bone[None, :]]
        self.pair_from_entry = (same_point & below).to(dtype)  # (P, K)
        self.pair_affine = self.pair_from_entry @ self.entry_affine  # (P,)
        self.pair_dense_index = self.pair_point * self.num_bones + self.pair_bone


@dataclass(frozen=True)
class _DataTerm:
    """The data term of every frame.

    Attributes:
        rotations: (F, B, 3, 3) world rotations ``G_b`` (relative to the reference pose).
        heads: (F, B, 3) world bone heads, metres.
        parts: (F, K, 3) ``A_me`` on the non-zero (point, bone) entries of the structure, metres.
        residual: (F, M, 3) mapped points minus targets, metres.
        point_weight: (M,) point weights.
        cost: (F,) weighted sum of squared residuals, m^2.
    """

    rotations: Tensor
    heads: Tensor
    parts: Tensor
    residual: Tensor
    point_weight: Tensor
    cost: Tensor


def _data_term(points: PointModel, coefficients: PointCoefficients, structure: PointStructure, rotmats: Tensor,
               translation: Tensor, targets_m: Tensor) -> _DataTerm:
    """The mapped points of (F, B, 3, 3) ``rotmats`` and (F, 3) ``translation`` against (F, M, 3) targets."""
    point_weight = points.weight.to(rotmats.dtype)
    rotations, heads = points.world_transforms(coefficients, rotmats, translation)
    entry_heads = heads[:, structure.entry_bone]
    parts = (rotations[:, structure.entry_bone] @ structure.entry_linear[..., None])[..., 0]
    parts = parts + structure.entry_affine[:, None] * entry_heads  # (F, K, 3): A_me on the non-zero entries
    residual = (parts.transpose(1, 2) @ structure.entry_to_point).transpose(1, 2) - targets_m
    cost = ((residual**2).sum(-1) * point_weight).sum(-1)
    return _DataTerm(rotations, heads, parts, residual, point_weight, cost)


@dataclass(frozen=True)
class _Penalties:
    """The regularisers of every frame added to the data cost.

    Attributes:
        cost: (F,) data cost plus pose prior, hinge, pelvis-tilt and smoothness terms, m^2.
        pull: (F, B, 3, 3) half the derivative of the Frobenius penalties w.r.t. the local rotations.
        translation_pull: (F, 3) half the derivative of the smoothness term w.r.t. the translation, metres.
        smooth_count: (F,) number of neighbours each frame is tied to.
    """

    cost: Tensor
    pull: Tensor
    translation_pull: Tensor
    smooth_count: Tensor


def _penalties(
    data_cost: Tensor, rotmats: Tensor, translation: Tensor, weights: PoseWeights, neighbours: _Neighbours | None
) -> _Penalties:
    """Add the regularisers of (F, B, 3, 3) ``rotmats`` and (F, 3) ``translation`` to the (F,) data cost."""
    dtype = rotmats.dtype
    eye = torch.eye(3, dtype=dtype)
    bone_prior = weights.bone_prior.to(dtype)
    pull = bone_prior[:, None, None] * (rotmats - eye)
    cost = data_cost + (bone_prior * ((rotmats - eye) ** 2).sum((-2, -1))).sum(-1) + weights.hinge_cost(rotmats)
    cost = cost + weights.pelvis_tilt_cost(rotmats)
    smooth_count = torch.zeros(rotmats.shape[0], dtype=dtype)
    translation_pull = torch.zeros_like(translation)
    if neighbours is not None and weights.smooth > 0:
        for other_rot, other_trans, mask in (
            (neighbours.prev_rot, neighbours.prev_trans, neighbours.prev_mask),
            (neighbours.next_rot, neighbours.next_trans, neighbours.next_mask),
        ):
            step_rot, step_trans = rotmats - other_rot, translation - other_trans
            cost = cost + weights.smooth * mask * ((step_rot**2).sum((-3, -2, -1)) + (step_trans**2).sum(-1))
            pull = pull + weights.smooth * mask[:, None, None, None] * step_rot
            translation_pull = translation_pull + weights.smooth * mask[:, None] * step_trans
            smooth_count = smooth_count + mask
    return _Penalties(cost, pull, translation_pull, smooth_count)


@dataclass(frozen=True)
class _NormalEquations:
    """Gauss-Newton gradient and Hessian of every frame (N = 3 + 3 B: translation, then ``eta_b`` per bone).

    Attributes:
        gradient: (F, N).
        hessian: (F, N, N).
        dense: (F, M * B, 3) ``U_mb`` scaled by the square root of the point weight, zero off the structure.
    """

    gradient: Tensor
    hessian: Tensor
    dense: Tensor


def _normal_equations(
    structure: PointStructure, data: _DataTerm, rotmats: Tensor, weights: PoseWeights, penalties: _Penalties
) -> _NormalEquations:
    """Gradient and Hessian of the data term, the Frobenius penalties and the smoothness of the translation."""
    dtype = rotmats.dtype
    num_frames, num_bones = rotmats.shape[:2]
    num_points = structure.num_points
    point_weight, heads, rotations = data.point_weight, data.heads, data.rotations
    eye = torch.eye(3, dtype=dtype)
    bone_prior = weights.bone_prior.to(dtype)
    # U_mb on the (point, bone) pairs where it can be non-zero.
    below = structure.pair_from_entry @ data.parts - structure.pair_affine[:, None] * heads[:, structure.pair_bone]
    pair_weight = point_weight[structure.pair_point]
    dense = below.new_zeros(num_frames, num_points * num_bones, 3)
    dense[:, structure.pair_dense_index] = below * pair_weight.sqrt()[:, None]
    scaled = dense.reshape(num_frames, num_points, 3 * num_bones)
    gram = (scaled.transpose(1, 2) @ scaled).reshape(num_frames, num_bones, 3, num_bones, 3)
    size = 3 * (1 + num_bones)
    hessian = gram.new_empty(num_frames, size, size)
    # J_mb = -[U_mb]_x, and [u]_x^T [v]_x = (u . v) I - v u^T.
    rot_block = hessian[:, 3:, 3:].view(num_frames, num_bones, 3, num_bones, 3)
    rot_block.copy_(gram.permute(0, 1, 4, 3, 2)).neg_()
    rot_block.diagonal(dim1=2, dim2=4).add_(torch.diagonal(gram, dim1=2, dim2=4).sum(-1)[..., None])
    weighted_below = below.new_zeros(num_frames, num_bones, 3).index_add_(
        1, structure.pair_bone, below * pair_weight[:, None]
    )
    cross = _skew(weighted_below).reshape(num_frames, num_bones * 3, 3)  # J_b^T J_t = [sum_m w_m U_mb]_x
    hessian[:, 3:, :3] = cross
    hessian[:, :3, 3:] = cross.transpose(1, 2)
    hessian[:, :3, :3] = point_weight.sum() * eye
    weighted_residual = data.residual * point_weight[None, :, None]
    gradient_trans = weighted_residual.sum(1) + penalties.translation_pull
    pair_cross = torch.linalg.cross(below, weighted_residual[:, structure.pair_point])
    gradient_rot = below.new_zeros(num_frames, num_bones, 3).index_add_(1, structure.pair_bone, pair_cross)
    # Penalties: <D [e_i]_x, X> in local axes, rotated to world axes by G_b.
    penalty_local = _vee_of_antisymmetric_part(rotmats.transpose(-1, -2) @ penalties.pull)
    gradient_rot = gradient_rot + (rotations @ penalty_local[..., None])[..., 0]
    gradient = torch.cat([gradient_trans, gradient_rot.reshape(num_frames, -1)], dim=1)
    rot_curvature = 2.0 * (bone_prior[None, :] + weights.smooth * penalties.smooth_count[:, None])
    diagonal = torch.diagonal(hessian, dim1=1, dim2=2)
    diagonal[:, :3] += (weights.smooth * penalties.smooth_count)[:, None]
    diagonal[:, 3:] += rot_curvature.repeat_interleave(3, dim=1)
    return _NormalEquations(gradient, hessian, dense)


def _add_hinge(normal: _NormalEquations, rotmats: Tensor, rotations: Tensor, weights: PoseWeights) -> None:
    """Add the hinge term ``(a . D d)^2`` to the gradient and Hessian, in place (nothing without hinges)."""
    if not (len(weights.hinge_bones) and weights.hinge > 0):
        return
    dtype = rotmats.dtype
    num_frames, num_bones = rotmats.shape[:2]
    # r = a . (D d); d r / d omega = ((D^T a) x d)^T... written v^T with v = d x (D^T a) up to sign:
    # J^T r = v r and J^T J = v v^T in local axes (then rotated to world axes by G_b).
    axes = weights.hinge_axes.to(dtype)
    directions = weights.hinge_directions.to(dtype)
    hinge_rot = rotmats[:, weights.hinge_bones]
    pulled = (hinge_rot.transpose(-1, -2) @ axes[:, :, None])[..., 0]  # D^T a, (F, H, 3)
    v_local = torch.linalg.cross(directions.expand_as(pulled), pulled)
    world = rotations[:, weights.hinge_bones]
    v_world = (world @ v_local[..., None])[..., 0]
    r = weights.hinge_residual(rotmats)
    index = 1 + weights.hinge_bones
    normal.gradient.view(num_frames, -1, 3)[:, index] += weights.hinge * v_world * r[..., None]
    blocks = normal.hessian[:, 3:, 3:].view(num_frames, num_bones, 3, num_bones, 3)
    for i, b in enumerate(weights.hinge_bones.tolist()):
        blocks[:, b, :, b, :] += weights.hinge * v_world[:, i, :, None] * v_world[:, i, None, :]


def _add_pelvis_tilt(normal: _NormalEquations, rotations: Tensor, weights: PoseWeights) -> None:
    """Add the pelvis-tilt term ``|D_root e_z - e_z|^2`` to the gradient and Hessian, in place (if weighted)."""
    if not weights.pelvis_tilt > 0:
        return
    # r = u - e_z, u = G_root e_z; d u / d eta = eta x u = -[u]_x eta.
    up = rotations[:, 0, :, 2]
    jac = -_skew(up)
    tilt = up - torch.tensor([0.0, 0.0, 1.0], dtype=rotations.dtype)
    normal.gradient[:, 3:6] += weights.pelvis_tilt * (jac.transpose(1, 2) @ tilt[..., None])[..., 0]
    normal.hessian[:, 3:6, 3:6] += weights.pelvis_tilt * (jac.transpose(1, 2) @ jac)


def _data_jacobian(dense: Tensor, residual: Tensor, point_weight: Tensor) -> tuple[Tensor, Tensor]:
    """The (F, 3 M, N) data Jacobian and (F, 3 M) residual, scaled by the square roots of the point weights."""
    num_frames, num_points = residual.shape[:2]
    num_bones = dense.shape[1] // num_points
    eye = torch.eye(3, dtype=residual.dtype)
    root_weight = point_weight.sqrt()
    jac_rot = -_skew(dense.reshape(num_frames, num_points, num_bones, 3))  # (F, M, B, 3, 3)
    jac_rot = jac_rot.permute(0, 1, 3, 2, 4).reshape(num_frames, num_points * 3, num_bones * 3)
    jac_trans = (root_weight[:, None, None] * eye).reshape(num_points * 3, 3).expand(num_frames, -1, -1)
    data_jacobian = torch.cat([jac_trans, jac_rot], dim=2)
    data_residual = (residual * root_weight[None, :, None]).reshape(num_frames, -1)
    return data_jacobian, data_residual


def frame_costs(
    points: PointModel,
    coefficients: PointCoefficients,
    structure: PointStructure,
    rotmats: Tensor,
    translation: Tensor,
    targets_m: Tensor,
    weights: PoseWeights,
    neighbours: _Neighbours | None,
    derivatives: bool = False,
    jacobian: bool = False,
):
    """Per-frame objective (and optionally its Gauss-Newton gradient and Hessian), neighbours held fixed.

    The derivatives are taken w.r.t. world-axis increments ``eta_b = G_b @ omega_b`` (rotating bone ``b``'s subtree
    about its head), which makes the data Jacobian simply ``-[U_mb]_x``; the Frobenius penalties have the same
    Gram matrix ``2 I`` in either axes. :func:`levenberg_marquardt_poses` maps the step back with ``G_b^T``.

    Args:
        points: the mapped-point model.
        coefficients: the person's coefficients, in the dtype of ``rotmats``.
        structure: :class:`PointStructure` of ``coefficients``.
        rotmats: (F, B, 3, 3) local-ref rotations.
        translation: (F, 3) root translations, metres.
        targets_m: (F, M, 3) metres.
        weights: regulariser weights.
        neighbours: the neighbouring frames for the smoothness term (``None``: no smoothness).
        derivatives: also return the world rotations (F, B, 3, 3), the gradient (F, N) and the Gauss-Newton
            Hessian (F, N, N), N = 3 + 3 B (translation first, then ``eta_b`` per bone).
        jacobian: with ``derivatives``, also return the data Jacobian (F, 3 M, N) and residual (F, 3 M), both
            scaled by the square roots of the point weights (for solvers that add unknowns, e.g. offsets).

    Returns:
        cost (F,) in m^2, or ``(cost, rotations, gradient, hessian)``, or with ``jacobian``
        ``(cost, rotations, gradient, hessian, data_jacobian, data_residual)``.
    """
    data = _data_term(points, coefficients, structure, rotmats, translation, targets_m)
    penalties = _penalties(data.cost, rotmats, translation, weights, neighbours)
    if not derivatives:
        return penalties.cost
    normal = _normal_equations(structure, data, rotmats, weights, penalties)
    _add_hinge(normal, rotmats, data.rotations, weights)
    _add_pelvis_tilt(normal, data.rotations, weights)
    if not jacobian:
        return penalties.cost, data.rotations, normal.gradient, normal.hessian
    data_jacobian, data_residual = _data_jacobian(normal.dense, data.residual, data.point_weight)
    return penalties.cost, data.rotations, normal.gradient, normal.hessian, data_jacobian, data_residual


_DAMPING = Damping(start=1e-6, grow=8.0, shrink=3.0, floor=1e-7, ceiling=1e7, attempts=3)
"""Start nearly at Gauss-Newton: Marquardt's damping (relative to the Hessian's diagonal) slows the directions that only
the small pose prior decides (e.g. how a twist splits between two spine bones, whose single rotations the points do
see), and the start is good enough for full steps; failures raise it. A rejected frame retries at once with more
damping (same derivatives), three levels per iteration."""


def levenberg_marquardt_poses(
    points: PointModel,
    coefficients: PointCoefficients,
    rotmats: Tensor,
    translation: Tensor,
    targets_m: Tensor,
    weights: PoseWeights,
    iterations: int,
    previous: tuple[Tensor, Tensor] | None = None,
    smooth: bool = True,
) -> tuple[Tensor, Tensor, Tensor]:
    """Refine the poses of consecutive frames (one chunk) by Levenberg-Marquardt, per frame in parallel.

    Args:
        points: the mapped-point model.
        coefficients: the person's coefficients (the solve runs in their dtype; float64 recommended).
        rotmats: (F, B, 3, 3) starting local-ref rotations.
        translation: (F, 3) starting root translations, metres.
        targets_m: (F, M, 3) metres.
        weights: regulariser weights.
        iterations: the most iterations (each one Gauss-Newton solve per frame).
        previous: the fixed frame before the chunk (rotations (B, 3, 3), translation (3,)), for smoothness.
        smooth: couple consecutive frames (``False`` for frames that are not consecutive).

    Returns:
        rotmats (F, B, 3, 3), translation (F, 3), and the final per-frame cost (F,) in m^2.
    """
    dtype = coefficients.linear_m.dtype
    rotmats, translation, targets_m = rotmats.to(dtype), translation.to(dtype), targets_m.to(dtype)
    structure = PointStructure(coefficients, points.subtree)

    def neighbours_of(state):  # a Jacobi sweep: every frame's neighbours held at their current values
        return _Neighbours(*state, previous) if smooth else None

    if iterations < 1:
        return rotmats, translation, frame_costs(points, coefficients, structure, rotmats, translation, targets_m,
                                                 weights, neighbours_of((rotmats, translation)))

    def linearize(state):
        neighbours = neighbours_of(state)
        cost, rotations, gradient, hessian = frame_costs(
            points, coefficients, structure, *state, targets_m, weights, neighbours, derivatives=True
        )
        return (ArrowSystem.blocks_only(hessian, gradient), rotations, neighbours), cost

    def trial(state, system, damping):
        arrow, rotations, neighbours = system
        rotmats, translation = state
        step = solve_damped(arrow, damping)  # a frame whose damped Hessian is not positive definite: no step
        world_step = step.block_step[:, 3:].reshape(rotmats.shape[0], -1, 3)
        local_step = (rotations.transpose(-1, -2) @ world_step[..., None])[..., 0]
        trial_state = (rotmats @ roma.rotvec_to_rotmat(local_step), translation + step.block_step[:, :3])
        cost = frame_costs(points, coefficients, structure, *trial_state, targets_m, weights, neighbours)
        return trial_state, torch.where(step.solved, cost, torch.full_like(cost, float("inf")))

    def select(mask, new, old):
        return (torch.where(mask[:, None, None, None], new[0], old[0]), torch.where(mask[:, None], new[1], old[1]))

    # Stop when no frame gains more than round-off (relative 1e-10 of its cost, or 1e-14 m^2).
    outcome = levenberg_marquardt(linearize, trial, (rotmats, translation), max_iterations=iterations,
                                  damping=_DAMPING, stop=Stop(relative=1e-10, absolute=1e-14), select=select,
                                  relinearize_last=False)
    rotmats, translation = outcome.state
    return rotmats, translation, outcome.cost.to(dtype)
