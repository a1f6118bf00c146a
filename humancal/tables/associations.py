"""Who each detection is: the canonical ``associations`` table as arrays, with one vectorized lookup.

A detection is named by ``(frame, view, det_id)``; its ``person_id`` is a person across views and frames, and
``-1`` means "not a person" (a false positive) or "not associated" (``docs/conventions.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.tables.schemas import validate_table

__all__ = ["Associations"]

_KEYS = ("frame", "view", "det_id")


def _encode(frame: np.ndarray, view: np.ndarray, det_id: np.ndarray, bases: tuple[int, int]) -> np.ndarray:
    """One int64 per key, ordered like the (frame, view, det_id) tuples."""
    return (frame * bases[0] + view) * bases[1] + det_id


@dataclass(frozen=True)
class Associations:
    """The person of every associated detection.

    Attributes:
        frame, view, det_id: (A,) int64 keys of the detections, each key once, all >= 0.
        person_id: (A,) int64 person ids (``-1``: not a person / not associated).
    """

    frame: np.ndarray
    view: np.ndarray
    det_id: np.ndarray
    person_id: np.ndarray

    def __post_init__(self) -> None:
        arrays = {name: np.asarray(getattr(self, name)).reshape(-1) for name in (*_KEYS, "person_id")}
        n = len(arrays["frame"])
        for name, a in arrays.items():
            if len(a) != n:
                raise ValueError(f"Associations.{name} has {len(a)} entries, frame has {n}")
            if n and not np.issubdtype(a.dtype, np.integer):
                if not (np.isfinite(a).all() and (a == np.round(a)).all()):
                    raise ValueError(f"Associations.{name} must hold integers, got {a.dtype} values {a[:5]}")
            arrays[name] = a.astype(np.int64)
        for name in _KEYS:
            if n and arrays[name].min() < 0:
                raise ValueError(f"Associations.{name} must be >= 0, got {arrays[name].min()}")
        if n and arrays["person_id"].min() < -1:
            raise ValueError(f"Associations.person_id must be >= -1 (-1: not a person), got {arrays['person_id'].min()}")
        for name, a in arrays.items():
            object.__setattr__(self, name, a)
        keys = self._codes(self.frame, self.view, self.det_id)
        order = np.argsort(keys, kind="stable")
        if n and (np.diff(keys[order]) == 0).any():
            dup = order[np.flatnonzero(np.diff(keys[order]) == 0)[0]]
            raise ValueError(
                f"Associations: detection (frame {self.frame[dup]}, view {self.view[dup]}, det_id {self.det_id[dup]}) "
                "is listed more than once"
            )
        object.__setattr__(self, "_sorted_keys", keys[order])
        object.__setattr__(self, "_order", order)

    def __len__(self) -> int:
        return int(len(self.frame))

    def _bases(self) -> tuple[int, int]:
        # fixed by the table's own largest view and det_id: lookups of larger ones simply miss
        view_base = int(self.view.max()) + 2 if len(self) else 1
        det_base = int(self.det_id.max()) + 2 if len(self) else 1
        return view_base, det_base

    def _codes(self, frame, view, det_id) -> np.ndarray:
        return _encode(frame, view, det_id, self._bases())

    @classmethod
    def from_table(cls, table: pd.DataFrame) -> Associations:
        """From a canonical ``associations`` table (or any frame with its four columns; others are ignored).

        Raises:
            ValueError: a column is missing, or a key is not valid or appears twice.
        """
        missing = [c for c in (*_KEYS, "person_id") if c not in table.columns]
        if missing:
            raise ValueError(f"associations table lacks columns {missing} (needs frame, view, det_id, person_id)")
        return cls(*(table[c].to_numpy() for c in (*_KEYS, "person_id")))

    def to_table(self, sequence: str) -> pd.DataFrame:
        """The canonical ``associations`` table."""
        table = pd.DataFrame({"sequence": sequence, "frame": self.frame, "view": self.view, "det_id": self.det_id,
                              "person_id": self.person_id})
        return validate_table(table, "associations")

    def row_of(self, frame: np.ndarray, view: np.ndarray, det_id: np.ndarray) -> np.ndarray:
        """The row of each given detection in these arrays, ``-1`` for detections not listed (vectorized).

        Args:
            frame, view, det_id: (D,) keys.

        Returns:
            (D,) int64 row indices.
        """
        frame, view, det_id = (np.asarray(a, dtype=np.int64).reshape(-1) for a in (frame, view, det_id))
        out = np.full(len(frame), -1, dtype=np.int64)
        if len(self) == 0 or len(frame) == 0:
            return out
        view_base, det_base = self._bases()
        known = (frame >= 0) & (view >= 0) & (view < view_base - 1) & (det_id >= 0) & (det_id < det_base - 1)
        codes = self._codes(frame[known], view[known], det_id[known])
        at = np.clip(np.searchsorted(self._sorted_keys, codes), 0, len(self) - 1)
        hit = self._sorted_keys[at] == codes
        out[np.flatnonzero(known)[hit]] = self._order[at[hit]]
        return out

    def person_of(self, frame: np.ndarray, view: np.ndarray, det_id: np.ndarray) -> np.ndarray:
        """The person of each given detection, ``-1`` for detections not listed (vectorized).

        Args:
            frame, view, det_id: (D,) keys (e.g. the fields of :class:`~humancal.tables.detections.DenseDetections`).

        Returns:
            (D,) int64 person ids.
        """
        row = self.row_of(frame, view, det_id)
        return np.where(row >= 0, self.person_id[np.maximum(row, 0)] if len(self) else -1, -1)

    def row_of_detections(self, detections) -> np.ndarray:
        """:meth:`row_of` for every row of dense detections (anything with ``frame``, ``view``, ``det_id``)."""
        return self.row_of(detections.frame, detections.view, detections.det_id)

    def person_of_detections(self, detections) -> np.ndarray:
        """:meth:`person_of` for every row of dense detections (anything with ``frame``, ``view``, ``det_id``)."""
        return self.person_of(detections.frame, detections.view, detections.det_id)
