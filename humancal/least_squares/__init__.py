"""The least-squares engine: Levenberg-Marquardt over arrow-shaped normal equations.

One damped Gauss-Newton iteration (:func:`levenberg_marquardt`, with its :class:`Damping` schedule and :class:`Stop`
rule) and one Schur-complement step (:func:`solve_damped` on an :class:`ArrowSystem`) serve every least-squares
problem of the library: the calibration's bundle adjustment over people (:mod:`humancal.calibration.bundle`), the
refinement's bundle adjustment over triangulated points (:mod:`humancal.fitting.joint_bundle`), and the retargeting's
per-frame pose solve and its pose-and-offset solve (:mod:`humancal.retarget.levenberg`,
:mod:`humancal.retarget.offsets`). Each problem writes only its residuals and their derivatives.

Example:
    >>> import torch
    >>> from humancal.least_squares import ArrowSystem, solve_damped
    >>> system = ArrowSystem.blocks_only(torch.eye(2).expand(3, 2, 2).double(), torch.ones(3, 2).double())
    >>> solve_damped(system, 0.0).block_step[0].round(decimals=6).tolist()
    [-1.0, -1.0]
"""

from humancal.least_squares.arrow import ArrowStep, ArrowSystem, solve_damped
from humancal.least_squares.levenberg import Damping, Outcome, Stop, levenberg_marquardt

__all__ = ["ArrowStep", "ArrowSystem", "solve_damped", "Damping", "Outcome", "Stop", "levenberg_marquardt"]
