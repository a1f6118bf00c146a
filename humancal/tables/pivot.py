"""Fast building blocks for pivoting the long tables (one row per joint) into dense arrays.

``np.unique(keys, axis=0)`` sorts rows as structured records and ``Series.map(dict)`` hashes every string:
on a 900-frame, 5-view capture (350,000 detection rows) the two took about a second per pivot, and the graph
pivots the same tables many times. Here the integer key columns are packed into one integer (their mixed-radix
code) before the sort, and joint names become positions in the vocabulary by one hashed lookup.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

__all__ = ["unique_rows", "name_codes", "has_repeats"]

_MAX_CODE = 2**62


def unique_rows(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of an integer key array, sorted, and the row of each input: exactly
    ``np.unique(keys, axis=0, return_inverse=True)``, with a flat ``inverse``.

    Args:
        keys: (N, K) integers (e.g. frame, view, det_id).

    Returns:
        ``(unique, inverse)``: (U, K) int64 distinct rows in lexicographic order, and (N,) int64 with
        ``unique[inverse] == keys``.
    """
    keys = np.asarray(keys, dtype=np.int64)
    if keys.ndim != 2:
        raise ValueError(f"keys must be a 2-D (N, K) array, got shape {keys.shape}")
    if len(keys) == 0:
        return keys.reshape(0, keys.shape[1]), np.zeros(0, dtype=np.int64)
    low = keys.min(axis=0)
    spans = [int(s) for s in keys.max(axis=0) - low + 1]
    if int(np.prod([float(s) for s in spans])) >= _MAX_CODE:  # too wide to pack: the general (slower) path
        unique, inverse = np.unique(keys, axis=0, return_inverse=True)
        return unique, inverse.reshape(-1).astype(np.int64)
    # C-order (row-major) mixed-radix codes sort like the rows themselves: lexicographically
    code = np.ravel_multi_index(tuple((keys - low).T), spans)
    unique_code, inverse = np.unique(code, return_inverse=True)
    unique = np.stack(np.unravel_index(unique_code, spans), axis=1).astype(np.int64) + low
    return unique, inverse.reshape(-1).astype(np.int64)


def name_codes(names: pd.Series, vocabulary: Sequence[str]) -> np.ndarray:
    """(N,) int64 index of each name in ``vocabulary``; -1 for a name outside it (or a missing value)."""
    return pd.Index(list(vocabulary)).get_indexer(names).astype(np.int64)


def has_repeats(cells: np.ndarray, num_cells: int) -> bool:
    """Whether any cell index occurs twice (e.g. ``row * NUM_JOINTS + joint``: one table row per array cell).

    Args:
        cells: (N,) integers in ``[0, num_cells)``.
        num_cells: the number of cells.
    """
    cells = np.asarray(cells, dtype=np.int64)
    return bool(len(cells)) and int(np.bincount(cells, minlength=num_cells).max()) > 1
