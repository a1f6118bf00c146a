"""The least-squares engine: the Schur step against a dense solve, and Levenberg-Marquardt on problems with a known
minimum (single and batched)."""

from __future__ import annotations

import pytest
import torch

from humancal.least_squares import ArrowSystem, Damping, Stop, levenberg_marquardt, solve_damped


def _random_arrow(generator: torch.Generator, n: int = 4, blocks: int = 6, m: int = 3) -> ArrowSystem:
    """The normal equations J^T J, J^T r of a random sparse-arrow Jacobian (positive definite)."""
    rows = 5 * m
    J_global = torch.randn(blocks, rows, n, generator=generator, dtype=torch.float64)
    J_block = torch.randn(blocks, rows, m, generator=generator, dtype=torch.float64)
    r = torch.randn(blocks, rows, generator=generator, dtype=torch.float64)
    return ArrowSystem(
        global_hessian=torch.einsum("bri,brj->ij", J_global, J_global) + torch.eye(n, dtype=torch.float64),
        block_hessian=J_block.transpose(1, 2) @ J_block,
        cross=J_block.transpose(1, 2) @ J_global,
        global_gradient=torch.einsum("bri,br->i", J_global, r),
        block_gradient=torch.einsum("bri,br->bi", J_block, r),
    )


def _dense(system: ArrowSystem) -> tuple[torch.Tensor, torch.Tensor]:
    n = system.num_global
    B, m = system.block_gradient.shape
    H = torch.zeros(n + B * m, n + B * m, dtype=torch.float64)
    H[:n, :n] = system.global_hessian
    for b in range(B):
        s = slice(n + b * m, n + (b + 1) * m)
        H[s, s] = system.block_hessian[b]
        H[s, :n] = system.cross[b]
        H[:n, s] = system.cross[b].T
    return H, torch.cat([system.global_gradient, system.block_gradient.reshape(-1)])


@pytest.mark.parametrize("damping", [0.0, 1e-2, 10.0])
def test_schur_step_equals_the_dense_damped_solve(damping):
    system = _random_arrow(torch.Generator().manual_seed(0))
    H, g = _dense(system)
    H = H + torch.diag(damping * H.diagonal() + 1e-12)
    expected = torch.linalg.solve(H, -g)
    step = solve_damped(system, damping)
    assert bool(step.solved.all())
    n = system.num_global
    torch.testing.assert_close(step.global_step, expected[:n], rtol=1e-9, atol=1e-10)
    torch.testing.assert_close(step.block_step.reshape(-1), expected[n:], rtol=1e-9, atol=1e-10)


def test_independent_blocks_take_their_own_damping_and_a_singular_block_no_step():
    generator = torch.Generator().manual_seed(1)
    A = torch.randn(3, 4, 4, generator=generator, dtype=torch.float64)
    H = A @ A.transpose(1, 2) + torch.eye(4, dtype=torch.float64)
    H[2] = -torch.eye(4, dtype=torch.float64)  # not positive definite: refused, not solved wrongly
    g = torch.randn(3, 4, generator=generator, dtype=torch.float64)
    damping = torch.tensor([0.0, 5.0, 0.0], dtype=torch.float64)
    step = solve_damped(ArrowSystem.blocks_only(H, g), damping)
    assert step.solved.tolist() == [True, True, False]
    for b in (0, 1):
        damped = H[b] + torch.diag(damping[b] * H[b].diagonal() + 1e-12)
        torch.testing.assert_close(step.block_step[b], torch.linalg.solve(damped, -g[b]))
    assert bool((step.block_step[2] == 0).all())
    with pytest.raises(ValueError, match="per-block damping"):
        solve_damped(_random_arrow(generator), damping)


class _SharedDecay:
    """Curves ``y_bi = a_b exp(-k t_i)``: one shared rate ``k`` (global), one amplitude per curve (blocks)."""

    def __init__(self, rate: float, amplitudes: torch.Tensor) -> None:
        self.t = torch.linspace(0.0, 3.0, 12, dtype=torch.float64)
        self.y = amplitudes[:, None] * torch.exp(-rate * self.t)

    def residuals(self, state):
        k, a = state
        return a[:, None] * torch.exp(-k * self.t) - self.y  # (B, T)

    def cost(self, state):
        return float((self.residuals(state) ** 2).sum())

    def linearize(self, state):
        k, a = state
        e = torch.exp(-k * self.t)
        J_k = (-a[:, None] * self.t * e)[..., None]  # (B, T, 1)
        J_a = e.expand(len(a), -1)[..., None]  # (B, T, 1)
        r = self.residuals(state)
        system = ArrowSystem(torch.einsum("bti,btj->ij", J_k, J_k), J_a.transpose(1, 2) @ J_a,
                             J_a.transpose(1, 2) @ J_k, torch.einsum("bti,bt->i", J_k, r),
                             torch.einsum("bti,bt->bi", J_a, r))
        return system, self.cost(state)

    def trial(self, state, system, damping):
        step = solve_damped(system, damping)
        new = (state[0] + step.global_step[0], state[1] + step.block_step[:, 0])
        return new, self.cost(new)


def test_levenberg_marquardt_finds_a_shared_rate_and_the_amplitudes_from_far():
    amplitudes = torch.tensor([1.0, 2.5, 0.4, 3.0], dtype=torch.float64)
    problem = _SharedDecay(rate=0.8, amplitudes=amplitudes)
    start = (torch.tensor(4.0, dtype=torch.float64), torch.ones(4, dtype=torch.float64))
    outcome = levenberg_marquardt(problem.linearize, problem.trial, start, max_iterations=100,
                                  stop=Stop(relative=1e-14))
    assert outcome.converged and outcome.cost < 1e-16
    assert abs(float(outcome.state[0]) - 0.8) < 1e-7
    torch.testing.assert_close(outcome.state[1], amplitudes, rtol=1e-7, atol=1e-9)
    assert outcome.system is not None  # linearised at the final state


def test_a_refused_step_grows_the_damping_and_the_start_is_kept_when_nothing_helps():
    calls = []

    def linearize(x):
        return None, float(x**2)

    def trial(x, system, damping):
        calls.append(damping)
        return x + 1.0, float((x + 1.0) ** 2)  # always uphill

    outcome = levenberg_marquardt(linearize, trial, 1.0, max_iterations=5, damping=Damping(attempts=4))
    assert outcome.state == 1.0 and outcome.converged and outcome.refused == 4 and outcome.iterations == 1
    assert calls == pytest.approx([1e-3, 1e-2, 1e-1, 1.0])
    with pytest.raises(FloatingPointError, match="starting cost"):
        levenberg_marquardt(lambda x: (None, float("nan")), trial, 1.0, max_iterations=5)
    with pytest.raises(ValueError, match="Damping"):
        Damping(start=1e-12, floor=1e-9)


def test_batched_problems_converge_each_with_its_own_damping():
    """B scalar problems ``min (x_b^2 - c_b)^2`` in lockstep: each ends at sqrt(c_b)."""
    targets = torch.tensor([4.0, 9.0, 0.25], dtype=torch.float64)

    def linearize(x):
        r = x**2 - targets
        J = 2 * x
        return ArrowSystem.blocks_only((J * J)[:, None, None], (J * r)[:, None]), r**2

    def trial(x, system, damping):
        new = x + solve_damped(system, damping).block_step[:, 0]
        return new, (new**2 - targets) ** 2

    outcome = levenberg_marquardt(linearize, trial, torch.ones(3, dtype=torch.float64), max_iterations=60,
                                  stop=Stop(relative=0.0, absolute=1e-24),
                                  select=lambda mask, new, old: torch.where(mask, new, old))
    torch.testing.assert_close(outcome.state, targets.sqrt(), rtol=1e-8, atol=1e-10)
    assert outcome.cost.shape == (3,)
    with pytest.raises(ValueError, match="select"):
        levenberg_marquardt(linearize, trial, torch.ones(3, dtype=torch.float64), max_iterations=1)
