"""Bottom-up detector output for one image: joint candidates and limb affinity scores."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CandidateFrame"]


@dataclass(frozen=True)
class CandidateFrame:
    """Joint candidates of one image and the part-affinity scores between them (no person identities yet).

    Attributes:
        xy_px: per joint type ``j``, (n_j, 2) candidate positions in pixels (x right, y down).
        score: per joint type ``j``, (n_j,) candidate confidences in [0, 1].
        paf: per limb ``k`` = (a, b) of ``limbs``, (n_a, n_b) affinity scores between the candidates of joint
            ``a`` (rows) and of joint ``b`` (columns); larger means more likely the same person, 0 means no link.
        limbs: (joint a, joint b) index pairs, one per entry of ``paf``.

    Raises:
        ValueError: inconsistent lengths or shapes, or non-finite values (the message names joint or limb).
    """

    xy_px: tuple[np.ndarray, ...]
    score: tuple[np.ndarray, ...]
    paf: tuple[np.ndarray, ...]
    limbs: tuple[tuple[int, int], ...]

    def __post_init__(self) -> None:
        xy = tuple(np.asarray(a, dtype=np.float64).reshape(-1, 2) for a in self.xy_px)
        score = tuple(np.asarray(s, dtype=np.float64).reshape(-1) for s in self.score)
        paf = tuple(np.atleast_2d(np.asarray(p, dtype=np.float64)) for p in self.paf)
        limbs = tuple((int(a), int(b)) for a, b in self.limbs)
        if len(xy) != len(score):
            raise ValueError(f"CandidateFrame: {len(xy)} joint position arrays but {len(score)} score arrays")
        if len(paf) != len(limbs):
            raise ValueError(f"CandidateFrame: {len(paf)} PAF matrices but {len(limbs)} limbs")
        n = [len(s) for s in score]
        for j, (p, s) in enumerate(zip(xy, score, strict=True)):
            if len(p) != len(s):
                raise ValueError(f"CandidateFrame: joint {j} has {len(p)} positions but {len(s)} scores")
            if not (np.isfinite(p).all() and np.isfinite(s).all()):
                raise ValueError(f"CandidateFrame: joint {j} has non-finite positions or scores")
        paf = list(paf)
        for k, ((a, b), m) in enumerate(zip(limbs, paf, strict=True)):
            if not (0 <= a < len(n) and 0 <= b < len(n)):
                raise ValueError(f"CandidateFrame: limb {k} ({a}, {b}) names a joint outside 0..{len(n) - 1}")
            if m.size == 0:
                m = np.zeros((n[a], n[b]))
                paf[k] = m
            if m.shape != (n[a], n[b]):
                raise ValueError(
                    f"CandidateFrame: limb {k} ({a}, {b}) PAF matrix has shape {m.shape}, expected ({n[a]}, {n[b]})"
                )
            if not np.isfinite(m).all():
                raise ValueError(f"CandidateFrame: limb {k} ({a}, {b}) PAF matrix has non-finite values")
        object.__setattr__(self, "xy_px", xy)
        object.__setattr__(self, "score", score)
        object.__setattr__(self, "paf", tuple(paf))
        object.__setattr__(self, "limbs", limbs)

    @property
    def num_joints(self) -> int:
        """Number of joint types."""
        return len(self.score)

    @property
    def num_candidates(self) -> tuple[int, ...]:
        """Number of candidates per joint type."""
        return tuple(len(s) for s in self.score)
