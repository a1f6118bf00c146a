"""Per-frame pose fit: position-based inverse kinematics on the body model, in chunks of consecutive frames.

Objective per frame (weights in ``RetargetConfig``): the weighted squared distances of the mapped points to the
mocap joints, ``pose_prior_weight * sum_{b > 0} scale_b |D_b - I|_F^2`` (decides what no point observes: twists,
toes, the split of a bend between the spine bones or of an arm raise between clavicle and upper arm; ``scale_b``
from ``bone_prior_scale``) and ``smooth_weight * (|D(t) - D(t-1)|_F^2 + |t(t) - t(t-1)|^2)``.

Each chunk starts from the analytic initialisation (:mod:`humancal.retarget.init`, every frame on its own, so no
error carries over from frame to frame) and is refined by batched Levenberg-Marquardt
(:mod:`humancal.retarget.levenberg`) in float64; the first frame of a chunk is tied by the smoothness term to the
last frame of the previous chunk, already solved.

:func:`pose_objective` is the same objective as one differentiable scalar (autograd), used by the shape fit.
"""

from __future__ import annotations

import logging

import roma
import torch
from torch import Tensor

from humancal.retarget.config import RetargetConfig
from humancal.retarget.init import analytic_pose_init
from humancal.retarget.levenberg import levenberg_marquardt_poses
from humancal.retarget.priors import PoseWeights
from humancal.retarget.points import PointCoefficients, PointModel

__all__ = ["pose_objective", "solve_poses", "fit_poses", "run_lbfgs"]

logger = logging.getLogger(__name__)


def pose_objective(
    points: PointModel,
    coefficients: PointCoefficients,
    bone_rotmats_local: Tensor,
    root_translation_m: Tensor,
    targets_m: Tensor,
    config: RetargetConfig,
) -> Tensor:
    """The shape-fit objective for fixed poses: the pose objective without smoothness, with the pelvis-tilt prior,
    averaged over frames (differentiable).

    Args:
        points: the mapped-point model.
        coefficients: the person's mapped-point coefficients.
        bone_rotmats_local: (F, B, 3, 3) local-ref rotations.
        root_translation_m: (F, 3) metres.
        targets_m: (F, M, 3) mocap positions, metres.
        config: the weights.

    Returns:
        Scalar loss, m^2.
    """
    num_frames = bone_rotmats_local.shape[0]
    predicted = points.points(coefficients, bone_rotmats_local, root_translation_m)
    squared = ((predicted - targets_m) ** 2).sum(dim=-1)
    loss = (squared * points.weight.to(squared.dtype)).sum() / num_frames
    eye = torch.eye(3, dtype=bone_rotmats_local.dtype, device=bone_rotmats_local.device)
    weights = PoseWeights.from_config(config, points, coefficients, smooth=False, shape_fit=True)
    bone_prior = weights.bone_prior.to(squared.dtype)
    prior = (bone_prior * ((bone_rotmats_local - eye) ** 2).sum((-2, -1))).sum()
    prior = prior + weights.hinge_cost(bone_rotmats_local).sum() + weights.pelvis_tilt_cost(bone_rotmats_local).sum()
    return loss + prior / num_frames


def run_lbfgs(parameters: list[Tensor], loss_fn, iterations: int, history: int) -> float:
    """Minimise ``loss_fn()`` over ``parameters`` with torch's L-BFGS and a strong-Wolfe line search.

    Returns:
        The final loss value.
    """
    optimizer = torch.optim.LBFGS(
        parameters,
        lr=1.0,
        max_iter=iterations,
        max_eval=int(iterations * 1.5) + 1,
        history_size=history,
        tolerance_grad=1e-12,
        tolerance_change=1e-15,
        line_search_fn="strong_wolfe",
    )

    def closure() -> Tensor:
        optimizer.zero_grad(set_to_none=False)
        loss = loss_fn()
        loss.backward()
        return loss

    optimizer.step(closure)
    with torch.no_grad():
        return float(loss_fn())


def solve_poses(
    points: PointModel,
    coefficients: PointCoefficients,
    targets_m: Tensor,
    config: RetargetConfig,
    smooth: bool,
    start: tuple[Tensor, Tensor] | None = None,
) -> tuple[Tensor, Tensor, Tensor]:
    """Analytic start (or a given one) + Levenberg-Marquardt for every frame, chunk by chunk.

    Args:
        points: the mapped-point model.
        coefficients: the person's coefficients; the solve runs in their dtype (float64 recommended).
        targets_m: (F, M, 3) metres.
        config: chunk size, iterations and weights.
        smooth: frames are consecutive (couple them by the smoothness term).
        start: starting rotations (F, B, 3, 3) and translations (F, 3) (a warm start); default: analytic.

    Returns:
        bone_rotmats_local (F, B, 3, 3), root_translation_m (F, 3), per-frame cost (F,) in m^2, in the
        coefficients' dtype.
    """
    dtype = coefficients.linear_m.dtype
    targets_m = targets_m.to(dtype)
    weights = PoseWeights.from_config(config, points, coefficients, smooth=smooth)
    rotmats_out, translation_out, cost_out = [], [], []
    previous = None
    for first in range(0, targets_m.shape[0], config.chunk_frames):
        chunk = slice(first, first + config.chunk_frames)
        target = targets_m[chunk]
        if start is None:
            rot0, trans0 = analytic_pose_init(points, coefficients, target, config.init_child_weight)
        else:
            rot0, trans0 = start[0][chunk], start[1][chunk]
        rotmats, translation, cost = levenberg_marquardt_poses(
            points, coefficients, rot0, trans0, target, weights, config.pose_iterations, previous, smooth
        )
        rotmats_out.append(rotmats)
        translation_out.append(translation)
        cost_out.append(cost)
        previous = (rotmats[-1], translation[-1]) if smooth else None
    return torch.cat(rotmats_out), torch.cat(translation_out), torch.cat(cost_out)


def fit_poses(
    points: PointModel,
    coefficients: PointCoefficients,
    targets_m: Tensor,
    config: RetargetConfig,
) -> tuple[Tensor, Tensor]:
    """Fit the pose of every frame of a clip (shape and offsets fixed).

    Args:
        points: the mapped-point model.
        coefficients: the person's mapped-point coefficients (shape and offsets), detached.
        targets_m: (F, M, 3) mocap positions of the mapped points, consecutive frames, metres.
        config: iterations, chunk size and weights.

    Returns:
        bone_rotmats_local: (F, B, 3, 3) and root_translation_m: (F, 3), in the body model's dtype (solved in
        float64; the rotations re-projected onto SO(3) before the cast).
    """
    rotmats, translation, cost = solve_poses(points, coefficients.to(torch.float64), targets_m, config, smooth=True)
    logger.debug("pose fit: %d frames, mean cost %.3g m^2", rotmats.shape[0], float(cost.mean()))
    dtype = points.body.dtype
    return roma.special_procrustes(rotmats).to(dtype), translation.to(dtype)
