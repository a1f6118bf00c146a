"""Fitted body motions of the people of a sequence: the product's main output, and its ``motions`` table.

One :class:`FittedMotions` holds every person of a sequence over the sequence's frames. A person is *present*
from the first to the last frame the association saw them (frames in between where they were hidden are
filled by the fit: the motion prior carries them); rows outside that span are not written to the table. Each
person keeps one id, so a person who leaves and comes back is still one person with one motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.body import PHENOTYPE_NAMES
from humancal.body.bones import POSED_BONE_NAMES
from humancal.keypoints import NUM_JOINTS
from humancal.tables.schemas import validate_table

__all__ = ["FittedMotions"]

_NUM_BONES = len(POSED_BONE_NAMES)


@dataclass(frozen=True)
class FittedMotions:
    """Body-model parameters and keypoints of P people over T frames (numpy, float64).

    Conventions (``docs/conventions.md``): world metres, Z up; rotations as matrices in anny's "local-ref"
    parameterization (world-aligned axes about each bone's head, composed child after parent), bone order
    ``humancal.body.bones.POSED_BONE_NAMES`` (bone 0, ``root``, is the body's global orientation).

    Attributes:
        person_ids: (P,) int, the association's person ids.
        frames: (T,) int, the sequence's frame numbers, increasing.
        present: (P, T) bool, True from each person's first to last observed frame.
        phenotypes: (P, 6) anny phenotypes in [0, 1], columns ``humancal.body.PHENOTYPE_NAMES``.
        bone_rotmats_local: (P, T, 22, 3, 3) posed-bone rotations, root first.
        root_translation_m: (P, T, 3) world position of the root bone head, metres.
        keypoints_world_m: (P, T, 23, 3) the fitted bodies' canonical keypoints, world metres.
        fps: frame rate, frames per second.
    """

    person_ids: np.ndarray
    frames: np.ndarray
    present: np.ndarray
    phenotypes: np.ndarray
    bone_rotmats_local: np.ndarray
    root_translation_m: np.ndarray
    keypoints_world_m: np.ndarray
    fps: float

    def __post_init__(self) -> None:
        P, T = len(self.person_ids), len(self.frames)
        expected = {
            "person_ids": (P,), "frames": (T,), "present": (P, T), "phenotypes": (P, len(PHENOTYPE_NAMES)),
            "bone_rotmats_local": (P, T, _NUM_BONES, 3, 3), "root_translation_m": (P, T, 3),
            "keypoints_world_m": (P, T, NUM_JOINTS, 3),
        }
        for name, shape in expected.items():
            value = getattr(self, name)
            if not isinstance(value, np.ndarray) or value.shape != shape:
                got = value.shape if isinstance(value, np.ndarray) else type(value).__name__
                raise ValueError(f"FittedMotions.{name} must be a numpy array of shape {shape}, got {got}")
        if len(set(self.person_ids.tolist())) != P:
            raise ValueError(f"FittedMotions.person_ids must be unique, got {self.person_ids.tolist()}")
        if T > 1 and not np.all(np.diff(self.frames) > 0):
            raise ValueError("FittedMotions.frames must be increasing")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"FittedMotions.fps={self.fps!r} must be > 0")

    @property
    def num_people(self) -> int:
        return int(len(self.person_ids))

    @property
    def num_frames(self) -> int:
        return int(len(self.frames))

    def person(self, person_id: int) -> FittedMotions:
        """The motion of one person over their present frames only (a one-person :class:`FittedMotions`)."""
        matches = np.flatnonzero(self.person_ids == person_id)
        if matches.size != 1:
            raise ValueError(f"no person {person_id} among the fitted people {self.person_ids.tolist()}")
        p = int(matches[0])
        keep = self.present[p]
        return FittedMotions(
            person_ids=self.person_ids[p : p + 1], frames=self.frames[keep], present=self.present[p : p + 1, keep],
            phenotypes=self.phenotypes[p : p + 1], bone_rotmats_local=self.bone_rotmats_local[p : p + 1, keep],
            root_translation_m=self.root_translation_m[p : p + 1, keep],
            keypoints_world_m=self.keypoints_world_m[p : p + 1, keep], fps=self.fps,
        )

    def to_table(self, sequence: str) -> pd.DataFrame:
        """The canonical ``motions`` table: one row per present (person, frame).

        ``bone_rotmats_local`` holds the 22 row-major 3x3 matrices (198 values), ``keypoints_world_m`` the 23
        keypoints (69 values), ``phenotypes`` the 6 phenotypes (the same on every row of a person).
        """
        p_idx, t_idx = np.nonzero(self.present)
        df = pd.DataFrame({
            "sequence": sequence,
            "person_id": self.person_ids[p_idx].astype(np.int32),
            "frame": self.frames[t_idx].astype(np.int32),
            "bone_rotmats_local": list(self.bone_rotmats_local[p_idx, t_idx].reshape(len(p_idx), -1)),
            "root_translation_m": list(self.root_translation_m[p_idx, t_idx]),
            "phenotypes": list(self.phenotypes[p_idx]),
            "keypoints_world_m": list(self.keypoints_world_m[p_idx, t_idx].reshape(len(p_idx), -1)),
        })
        return validate_table(df, "motions", source="FittedMotions.to_table")

    @classmethod
    def from_table(cls, df: pd.DataFrame, fps: float) -> FittedMotions:
        """The motions of one sequence back from its ``motions`` table (the inverse of :meth:`to_table`).

        Frames run from the table's first to last frame; a person's rows outside their span are absent, so
        their ``present`` is False there (values copied from the nearest present frame).

        Raises:
            ValueError: the table fails its schema, holds several sequences or no rows, lists of the wrong length,
                a (person, frame) twice, or a person whose phenotypes change.
        """
        table = validate_table(df, "motions", source="FittedMotions.from_table")
        sequences = table["sequence"].unique().tolist()
        if len(sequences) != 1:
            raise ValueError(f"FittedMotions.from_table reads one sequence's motions, got sequences {sequences}")
        if table.duplicated(["person_id", "frame"]).any():
            raise ValueError("motions table: a (person_id, frame) appears twice")
        person_ids = np.array(sorted(table["person_id"].unique()), dtype=np.int64)
        frames = np.arange(int(table["frame"].min()), int(table["frame"].max()) + 1)
        P, T = len(person_ids), len(frames)

        def column(name: str, width: int) -> np.ndarray:
            lengths = {len(v) for v in table[name]}
            if lengths != {width}:
                raise ValueError(f"motions table: column {name!r} must hold {width} values per row, got {sorted(lengths)}")
            return np.stack([np.asarray(v, dtype=np.float64) for v in table[name]])

        rot = column("bone_rotmats_local", _NUM_BONES * 9).reshape(-1, _NUM_BONES, 3, 3)
        trans = column("root_translation_m", 3)
        pheno = column("phenotypes", len(PHENOTYPE_NAMES))
        kp = column("keypoints_world_m", NUM_JOINTS * 3).reshape(-1, NUM_JOINTS, 3)
        p_idx = np.searchsorted(person_ids, table["person_id"].to_numpy())
        t_idx = table["frame"].to_numpy() - frames[0]
        present = np.zeros((P, T), bool)
        present[p_idx, t_idx] = True
        phenotypes = np.zeros((P, len(PHENOTYPE_NAMES)))
        for p in range(P):
            rows = pheno[p_idx == p]
            if not np.allclose(rows, rows[0], rtol=0, atol=1e-12):
                raise ValueError(f"motions table: the phenotypes of person {person_ids[p]} change over frames")
            phenotypes[p] = rows[0]
        out = {"rot": np.tile(np.eye(3), (P, T, _NUM_BONES, 1, 1)), "trans": np.zeros((P, T, 3)),
               "kp": np.zeros((P, T, NUM_JOINTS, 3))}
        for key, values in (("rot", rot), ("trans", trans), ("kp", kp)):
            out[key][p_idx, t_idx] = values
            for p in range(P):  # absent frames: the nearest present frame (never written back to a table)
                good = np.flatnonzero(present[p])
                nearest = good[np.abs(np.arange(T)[:, None] - good[None, :]).argmin(axis=1)]
                out[key][p] = out[key][p, nearest]
        return cls(person_ids=person_ids, frames=frames, present=present, phenotypes=phenotypes,
                   bone_rotmats_local=out["rot"], root_translation_m=out["trans"], keypoints_world_m=out["kp"],
                   fps=float(fps))
