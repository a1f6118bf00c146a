"""The damped Gauss-Newton step of an arrow-shaped system, by the Schur complement.

Every least-squares problem of humancal has the same structure: a few *global* unknowns that many residuals share
(the cameras of a bundle adjustment, the correspondence offsets of a retargeting) and many small *blocks* of
unknowns that touch only their own residuals and the global ones (a point, the keypoints of one person in one
frame, one frame's pose). Its normal equations form an arrow::

    [ H_gg    H_bg^T ] [ d_g ]     [ g_g ]
    [ H_bg    H_bb   ] [ d_b ] = - [ g_b ]      H_bb block-diagonal: B blocks of m x m

The blocks are eliminated (Schur complement), the reduced global system ``S = H_gg - H_bg^T H_bb^-1 H_bg`` is
solved, and the block steps follow by back-substitution: the cost is linear in the number of blocks.

Damping is Marquardt's: every diagonal entry grows by the factor ``1 + damping`` (plus ``epsilon``, which keeps a
parameter that no residual touches from making the system singular). A problem without global unknowns (``n = 0``)
is B independent problems, each with its own damping (a tensor of shape (B,)).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["ArrowSystem", "ArrowStep", "solve_damped"]


@dataclass(frozen=True)
class ArrowSystem:
    """Normal equations ``H d = -g`` with the arrow structure of the module docstring (one dtype throughout).

    Attributes:
        global_hessian: (n, n) ``H_gg``; n may be 0.
        block_hessian: (B, m, m) the diagonal blocks of ``H_bb``.
        cross: (B, m, n) ``H_bg``: how each block's residuals couple it to the global unknowns.
        global_gradient: (n,) ``g_g``.
        block_gradient: (B, m) ``g_b``.
    """

    global_hessian: Tensor
    block_hessian: Tensor
    cross: Tensor
    global_gradient: Tensor
    block_gradient: Tensor

    @classmethod
    def blocks_only(cls, block_hessian: Tensor, block_gradient: Tensor) -> ArrowSystem:
        """B independent problems: (B, m, m) Hessians and (B, m) gradients, no global unknowns."""
        B, m = block_gradient.shape
        like = block_gradient
        return cls(like.new_zeros(0, 0), block_hessian, like.new_zeros(B, m, 0), like.new_zeros(0), block_gradient)

    @property
    def num_global(self) -> int:
        return int(self.global_gradient.shape[0])


@dataclass(frozen=True)
class ArrowStep:
    """A damped step.

    Attributes:
        global_step: (n,) ``d_g``.
        block_step: (B, m) ``d_b`` (zeros for a block whose damped Hessian is not positive definite).
        solved: (B,) whether each block's step is a solution: its damped Hessian and, when there are global
            unknowns, the reduced system were positive definite (then every block shares the reduced system's
            verdict).
        reduced: (n, n) the damped reduced system ``S`` (its inverse is the covariance of the global unknowns when
            the damping is zero).
        blocks_factored: (B,) whether each block's damped Hessian was positive definite (``reduced`` is exact only
            where all were).
    """

    global_step: Tensor
    block_step: Tensor
    solved: Tensor
    reduced: Tensor
    blocks_factored: Tensor


def _damped(matrix: Tensor, damping: Tensor | float, epsilon: float) -> Tensor:
    """``matrix`` (..., k, k) with its diagonal times ``1 + damping`` plus ``epsilon``; ``damping`` broadcasts over
    the leading dimensions."""
    damping = torch.as_tensor(damping, dtype=matrix.dtype)
    diagonal = torch.diagonal(matrix, dim1=-2, dim2=-1)
    grown = diagonal * (1.0 + damping.reshape(damping.shape + (1,) * (diagonal.dim() - damping.dim()))) + epsilon
    return matrix + torch.diag_embed(grown - diagonal)


def solve_damped(system: ArrowSystem, damping: Tensor | float, *, epsilon: float = 1e-12) -> ArrowStep:
    """The Levenberg-Marquardt step of ``system`` (module docstring).

    Args:
        system: the normal equations.
        damping: Marquardt's damping, a scalar, or (B,) per block when the system has no global unknowns.
        epsilon: added to every damped diagonal entry.

    Returns:
        :class:`ArrowStep`. Nothing raises on a singular or indefinite system: ``solved`` says where it was.
    """
    H_bb, cross, g_b = system.block_hessian, system.cross, system.block_gradient
    B, m = g_b.shape
    n = system.num_global
    damping = torch.as_tensor(damping, dtype=g_b.dtype)
    if damping.dim() and n:
        raise ValueError(f"solve_damped: per-block damping {tuple(damping.shape)} needs a system without global "
                         f"unknowns (it has {n})")
    factor, info = torch.linalg.cholesky_ex(_damped(H_bb, damping, epsilon))
    block_ok = info == 0
    # H_bb^-1 [g_b | H_bg] in one batched solve (identity where a block failed: its step is discarded)
    safe = torch.where(block_ok[:, None, None], factor, torch.eye(m, dtype=g_b.dtype).expand(B, m, m))
    solved = torch.cholesky_solve(torch.cat([g_b[..., None], cross], dim=2), safe)
    inv_g, inv_cross = solved[..., 0], solved[..., 1:]
    if n == 0:
        step_b = torch.where(block_ok[:, None], -inv_g, torch.zeros_like(inv_g))
        return ArrowStep(g_b.new_zeros(0), step_b, block_ok, g_b.new_zeros(0, 0), block_ok)
    reduced = _damped(system.global_hessian, damping, epsilon) - torch.einsum("bmi,bmj->ij", cross, inv_cross)
    rhs = -system.global_gradient + torch.einsum("bmi,bm->i", cross, inv_g)
    step_g, info_g = torch.linalg.solve_ex(reduced, rhs)
    ok = bool(block_ok.all()) and int(info_g) == 0 and bool(torch.isfinite(step_g).all())
    step_b = -(inv_g + inv_cross @ step_g)
    return ArrowStep(step_g, step_b, torch.full((B,), ok, dtype=torch.bool), reduced, block_ok)
