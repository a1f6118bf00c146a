"""Levenberg-Marquardt: the one iteration that every least-squares problem of humancal runs.

A problem supplies two functions:

* ``linearize(state) -> (system, cost)``: its normal equations at ``state`` (usually an
  :class:`~humancal.least_squares.arrow.ArrowSystem`, reweighted for a robust loss) and its cost there;
* ``trial(state, system, damping) -> (state, cost)``: the state after the damped step and its cost, ``inf`` (or
  NaN) where the step failed (a singular system, non-finite values).

The driver keeps a step only where it lowers the cost and is finite; a refused step grows the damping and is tried
again from the same linearisation, up to :attr:`Damping.attempts` times; an accepted one shrinks it. It stops when no
step lowers the cost (converged, or stuck at the last good state), when the cost's decrease falls under
:class:`Stop`'s tolerance, when the problem's own ``stop`` says so, or after ``max_iterations``.

*Batched* problems (B independent problems solved in lockstep, e.g. one pose per frame) give a cost of shape (B,);
each has its own damping and acceptance, and ``select(mask, new, old)`` picks the accepted ones from a trial state.
A single problem gives a scalar cost (a Python float or a 0-d tensor).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

__all__ = ["Damping", "Stop", "Outcome", "levenberg_marquardt"]


@dataclass(frozen=True)
class Damping:
    """The damping schedule (Marquardt's scaling: a step solves ``(H + damping diag(H)) d = -g``).

    Attributes:
        start: the first iteration's damping.
        grow: factor on the damping after a refused step.
        shrink: divisor on the damping after an accepted step.
        floor, ceiling: the damping stays within these.
        attempts: steps tried from one linearisation before the iteration gives up on a problem.
    """

    start: float = 1e-3
    grow: float = 10.0
    shrink: float = 3.0
    floor: float = 1e-9
    ceiling: float = 1e7
    attempts: int = 10

    def __post_init__(self) -> None:
        if not (0.0 < self.floor <= self.start <= self.ceiling and self.grow > 1.0 and self.shrink > 1.0
                and self.attempts >= 1):
            raise ValueError(f"Damping: need 0 < floor <= start <= ceiling, grow > 1, shrink > 1, attempts >= 1; "
                             f"got {self}")


@dataclass(frozen=True)
class Stop:
    """When an accepted step is the last: every problem's decrease ``gain <= relative * cost_before + absolute``."""

    relative: float = 1e-6
    absolute: float = 0.0


@dataclass(frozen=True)
class Outcome:
    """The result of :func:`levenberg_marquardt`.

    Attributes:
        state: the last state that lowered the cost (the start when none did).
        cost: its cost (a float for a single problem, a (B,) float64 tensor for a batch).
        system: the linearisation at ``state`` (None when the last iteration's steps were accepted but the
            problem stopped before linearising again).
        iterations: iterations run (linearisations whose steps were tried).
        refused: steps refused (summed over the problems of a batch).
        converged: whether it stopped because the cost stopped falling (not ``max_iterations``).
    """

    state: Any
    cost: Any
    system: Any
    iterations: int
    refused: int
    converged: bool


def _as_costs(cost: Any) -> Tensor:
    values = torch.as_tensor(cost, dtype=torch.float64)
    return values.reshape(-1)


@dataclass(frozen=True)
class _Attempts:
    """The outcome of one iteration's damped steps (B problems; B = 1 for a single problem).

    Attributes:
        state: the state with every accepted problem's step (the old state where none was accepted).
        costs: (B,) float64 costs of ``state``.
        accept: (B,) bool, which problems accepted a step.
        lam: (B,) float64 damping after the attempts (grown after every refusal).
        refused: steps refused, summed over the attempts and problems.
    """

    state: Any
    costs: Tensor
    accept: Tensor
    lam: Tensor
    refused: int


def _attempt_steps(
    trial: Callable[[Any, Any, Any], tuple[Any, Any]],
    state: Any,
    system: Any,
    costs: Tensor,
    lam: Tensor,
    damping: Damping,
    select: Callable[[Tensor, Any, Any], Any] | None,
) -> _Attempts:
    """Try damped steps from one linearisation until every problem has lowered its cost or the attempts run out."""
    batched = select is not None
    accept = torch.zeros(costs.numel(), dtype=torch.bool)
    new_state, new_costs, refused = state, costs, 0
    for _ in range(damping.attempts):
        current = lam if batched else float(lam[0])
        trial_state, trial_cost = trial(state, system, current)
        trial_costs = _as_costs(trial_cost)
        better = torch.isfinite(trial_costs) & (trial_costs < costs) & ~accept
        if batched:
            new_state = select(better, trial_state, new_state)
        elif bool(better[0]):
            new_state = trial_state
        new_costs = torch.where(better, trial_costs, new_costs)
        accept |= better
        refused += int((~accept).sum())
        if bool(accept.all()):
            break
        lam = torch.where(accept, lam, (lam * damping.grow).clamp(max=damping.ceiling))
    return _Attempts(new_state, new_costs, accept, lam, refused)


def levenberg_marquardt(
    linearize: Callable[[Any], tuple[Any, Any]],
    trial: Callable[[Any, Any, Any], tuple[Any, Any]],
    state: Any,
    *,
    max_iterations: int,
    damping: Damping = Damping(),
    stop: Stop = Stop(),
    select: Callable[[Tensor, Any, Any], Any] | None = None,
    accepted: Callable[[Any, Any], tuple[Any, bool]] | None = None,
    relinearize_last: bool = True,
) -> Outcome:
    """Minimise a problem by Levenberg-Marquardt (module docstring).

    Args:
        linearize: ``state -> (system, cost)``.
        trial: ``(state, system, damping) -> (new_state, new_cost)``; ``damping`` is a float for a single problem
            and a (B,) tensor for a batch.
        state: the starting state.
        max_iterations: the most iterations.
        damping: the schedule.
        stop: the tolerance on the cost's decrease.
        select: ``(mask (B,), new_state, old_state) -> state``: given, the problem is a batch (its cost (B,), even
            for B = 1); required when the cost has more than one element.
        accepted: ``(old_state, new_state) -> (state, stop)`` called after every accepted iteration: a problem's
            own bookkeeping (e.g. folding a rotation increment into its reference) and its own reason to stop.
        relinearize_last: linearise once more at the final state when the iterations end on an accepted step
            (callers that read the final system need it; others save one linearisation).

    Raises:
        FloatingPointError: the starting cost is not finite.
    """
    system, cost = linearize(state)
    costs = _as_costs(cost)
    if not torch.isfinite(costs).all():
        raise FloatingPointError(f"levenberg_marquardt: the starting cost is {costs.tolist()[:5]}")
    batch, batched = costs.numel(), select is not None
    if batch > 1 and not batched:
        raise ValueError(f"levenberg_marquardt: a cost of {batch} problems needs select=")
    lam = torch.full((batch,), damping.start, dtype=torch.float64)
    refused, converged, iterations, fresh = 0, False, 0, True
    for iterations in range(1, max_iterations + 1):
        attempts = _attempt_steps(trial, state, system, costs, lam, damping, select)
        new_state, new_costs, accept, lam = attempts.state, attempts.costs, attempts.accept, attempts.lam
        refused += attempts.refused
        if not bool(accept.any()):
            converged = True
            break
        lam = torch.where(accept, (lam / damping.shrink).clamp(min=damping.floor), lam)
        gain = costs - new_costs
        done = bool((gain <= stop.relative * costs + stop.absolute).all())
        if accepted is not None:
            new_state, own_stop = accepted(state, new_state)
            done = done or own_stop
        state, costs = new_state, new_costs
        if done:
            converged = True
            fresh = False
            break
        system, cost = linearize(state)
        costs = _as_costs(cost)
    else:
        fresh = True
    if not fresh and relinearize_last:
        system, cost = linearize(state)
        costs, fresh = _as_costs(cost), True
    final = costs if batched else float(costs[0])
    return Outcome(state, final, system if fresh else None, iterations, refused, converged)
