"""The settings of the cycle-consistent matching (:func:`humancal.association.cycle_matching.match_frames`): the
relaxation's threshold and low-rank weight, its ADMM solver, the rounding; apart from the code that reads them, so
that the batched solve (:mod:`~humancal.association.cycle_batching`) and the tracking's settings can name the type."""

from __future__ import annotations

from dataclasses import dataclass, field

from humancal.config import Config, at_least, in_range, positive

__all__ = ["MatchingConfig"]


@dataclass(frozen=True)
class MatchingConfig(Config):
    """Settings of the relaxation, its ADMM solver and the rounding.

    Attributes:
        match_threshold: affinity a pair must exceed to gain from being matched (the objective adds
            ``affinity - match_threshold`` per matched pair), in [0, 1].
        low_rank_weight: weight of the nuclear-norm (low-rank) penalty, >= 0 (see the module docstring).
        rho: initial ADMM penalty, > 0; adapted by residual balancing.
        over_relaxation: ADMM over-relaxation factor in [1, 2) (1: plain ADMM).
        tolerance: stop when the primal and dual residuals per matrix entry (Frobenius norm / N) are both below it
            (> 0).
        max_iterations: iteration cap per problem (an integer >= 1).
        rounding_threshold: relaxed value above which a pair is joined when rounding, in [0.5, 1) (0.5 or more
            keeps at most one partner per view and row).
        decompose: solve the connected parts of the pairs above ``match_threshold`` separately (exact; faster).
    """

    match_threshold: float = field(default=0.5, metadata=in_range(0, 1))
    low_rank_weight: float = field(default=0.05, metadata=at_least(0))
    rho: float = field(default=0.5, metadata=positive())
    over_relaxation: float = field(default=1.0, metadata=in_range(1, 2, high_open=True))
    tolerance: float = field(default=1e-3, metadata=positive())
    max_iterations: int = field(default=300, metadata=at_least(1, integer=True))
    rounding_threshold: float = field(default=0.5, metadata=in_range(0.5, 1, high_open=True))
    decompose: bool = True
