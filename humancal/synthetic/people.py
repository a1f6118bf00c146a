"""Random people: anny phenotypes that hit a sampled standing height."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import torch

from humancal.body import PHENOTYPE_NAMES, BodyModel

__all__ = ["People", "sample_people", "phenotypes_for_heights"]

logger = logging.getLogger(__name__)

_HEIGHT_COLUMN = PHENOTYPE_NAMES.index("height")
_HEIGHT_TOLERANCE_M = 5e-4
_SECANT_STEPS = 12
_SOLVE_TOLERANCE_M = 1e-5
_MAX_RESAMPLES = 20


@dataclass(frozen=True)
class People:
    """The people of a scene.

    Attributes:
        person_ids: (P,) distinct person ids (0..P-1).
        phenotypes: (P, 6) anny phenotypes in [0, 1], columns ``humancal.body.PHENOTYPE_NAMES``.
        height_m: (P,) standing height of each body (``BodyModel.height_m``), metres.
    """

    person_ids: np.ndarray
    phenotypes: np.ndarray
    height_m: np.ndarray

    @property
    def num_people(self) -> int:
        """P."""
        return int(self.person_ids.shape[0])


def _heights(body: BodyModel, phenotypes: np.ndarray) -> np.ndarray:
    tensor = torch.as_tensor(phenotypes, dtype=body.dtype, device=body.device)
    with torch.no_grad():
        return body.height_m(tensor).double().cpu().numpy()


def phenotypes_for_heights(body: BodyModel, phenotypes: np.ndarray, target_height_m: np.ndarray) -> np.ndarray:
    """Solve the ``height`` phenotype so that each body reaches its target height (others kept).

    Height grows monotonically (in anny nearly linearly) with the ``height`` phenotype, so a vectorised
    bracketing secant search (regula falsi, Illinois variant) over all people at once converges in a handful
    of body-model calls.

    Args:
        body: the body model.
        phenotypes: (P, 6) phenotypes in [0, 1]; the ``height`` column is ignored.
        target_height_m: (P,) wanted standing heights, metres.

    Returns:
        (P, 6) phenotypes with the ``height`` column solved, float64.

    Raises:
        ValueError: wrong shapes, or a target outside the heights reachable with the other phenotypes as
            given (the message names the person and the reachable range).
    """
    phenotypes = np.array(phenotypes, dtype=np.float64)
    target = np.asarray(target_height_m, dtype=np.float64)
    if phenotypes.ndim != 2 or phenotypes.shape[1] != len(PHENOTYPE_NAMES) or target.shape != phenotypes.shape[:1]:
        raise ValueError(
            f"phenotypes must be (P, {len(PHENOTYPE_NAMES)}) and target_height_m (P,), "
            f"got {phenotypes.shape} and {target.shape}"
        )
    h_low, h_high = _reachable_heights(body, phenotypes)
    bad = np.flatnonzero((target < h_low) | (target > h_high))
    if bad.size:
        p = int(bad[0])
        raise ValueError(
            f"target_height_m[{p}]={target[p]:.3f} m is unreachable with these phenotypes; "
            f"reachable: [{h_low[p]:.3f}, {h_high[p]:.3f}] m"
        )
    return _solve_height_column(body, phenotypes, target, h_low, h_high)


def _solve_height_column(
    body: BodyModel, phenotypes: np.ndarray, target: np.ndarray, h_low: np.ndarray, h_high: np.ndarray
) -> np.ndarray:
    """Regula falsi on the height column, given the heights at 0 and 1 that bracket every target."""
    lo, hi = np.zeros(len(target)), np.ones(len(target))
    f_lo, f_hi = h_low - target, h_high - target
    trial = phenotypes.copy()
    for _ in range(_SECANT_STEPS):
        x = np.clip(lo - f_lo * (hi - lo) / np.where(f_hi - f_lo > 0, f_hi - f_lo, 1.0), lo, hi)
        trial[:, _HEIGHT_COLUMN] = x
        f_x = _heights(body, trial) - target
        if np.abs(f_x).max() < _SOLVE_TOLERANCE_M:
            break
        above = f_x > 0
        # Illinois: halve the value at the end point that stays, so the bracket keeps shrinking from both sides.
        f_lo = np.where(above, f_lo * 0.5, f_x)
        f_hi = np.where(above, f_x, f_hi * 0.5)
        lo = np.where(above, lo, x)
        hi = np.where(above, x, hi)
    return trial


def _reachable_heights(body: BodyModel, phenotypes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P,) heights with the ``height`` phenotype at 0 and at 1, metres (one body-model call)."""
    both = np.concatenate([phenotypes, phenotypes])
    both[: len(phenotypes), _HEIGHT_COLUMN] = 0.0
    both[len(phenotypes) :, _HEIGHT_COLUMN] = 1.0
    heights = _heights(body, both)
    return heights[: len(phenotypes)], heights[len(phenotypes) :]


def _draw_body_types(rng: np.random.Generator, count: int) -> np.ndarray:
    """Adult phenotypes (the height column is a placeholder, solved later)."""
    columns = {
        # Mostly clearly female or male bodies, some in between.
        "gender": rng.beta(0.5, 0.5, count),
        # anny: 2/3 = young adult (25 y), 1 = old (90 y); this spans roughly 20 to 75 years.
        "age": rng.uniform(0.62, 0.92, count),
        "muscle": 0.2 + 0.6 * rng.beta(2.0, 2.0, count),
        "weight": 0.15 + 0.7 * rng.beta(2.0, 2.0, count),
        "height": np.full(count, 0.5),
        "proportions": rng.uniform(0.3, 0.7, count),
    }
    return np.stack([columns[name] for name in PHENOTYPE_NAMES], axis=1)


def sample_people(
    body: BodyModel,
    num_people: int,
    rng: np.random.Generator,
    height_range_m: tuple[float, float] = (1.5, 1.95),
) -> People:
    """Draw ``num_people`` adults of varied build whose heights are uniform in ``height_range_m``.

    Args:
        body: the body model (its ``height_m`` defines height).
        num_people: P >= 1.
        rng: source of randomness.
        height_range_m: (min, max) standing height, metres.

    Returns:
        :class:`People` with ids 0..P-1.

    Raises:
        ValueError: ``num_people`` < 1, or no body type reaches a drawn height after repeated draws.
    """
    if num_people < 1:
        raise ValueError(f"num_people={num_people} must be >= 1")
    target = rng.uniform(height_range_m[0], height_range_m[1], num_people)
    phenotypes = _draw_body_types(rng, num_people)
    for attempt in range(_MAX_RESAMPLES):
        h_low, h_high = _reachable_heights(body, phenotypes)
        unreachable = (target < h_low) | (target > h_high)
        if not unreachable.any():
            break
        logger.debug("attempt %d: redrawing %d body type(s) that cannot reach their height", attempt, unreachable.sum())
        phenotypes[unreachable] = _draw_body_types(rng, int(unreachable.sum()))
    else:
        raise ValueError(
            f"no anny body type reaches the heights {target.round(3).tolist()} m after {_MAX_RESAMPLES} draws"
        )
    phenotypes = _solve_height_column(body, phenotypes, target, h_low, h_high)
    # Store exactly what the body model sees (its dtype), so tables reproduce the bodies bit for bit.
    phenotypes = torch.as_tensor(phenotypes, dtype=body.dtype).double().numpy()
    height = _heights(body, phenotypes)
    if np.abs(height - target).max() > _HEIGHT_TOLERANCE_M:
        raise RuntimeError(f"height solve missed its targets by {np.abs(height - target).max() * 1000:.2f} mm")
    return People(person_ids=np.arange(num_people, dtype=np.int64), phenotypes=phenotypes, height_m=height)
