"""Dense array views of the long ``poses3d`` table."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.tables.pivot import name_codes, unique_rows

__all__ = ["DensePoses", "poses_to_dense"]


@dataclass(frozen=True)
class DensePoses:
    """3D poses as arrays, one row per (frame, person_id).

    Attributes:
        frame, person_id: (N,) identifiers.
        joints_world_m: (N, J, 3) world positions, metres (NaN where absent or invalid).
        valid: (N, J) True where the joint is present and valid.
        joint_names: the J joint names, in array order.
    """

    frame: np.ndarray
    person_id: np.ndarray
    joints_world_m: np.ndarray
    valid: np.ndarray
    joint_names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.frame)


def poses_to_dense(poses: pd.DataFrame, joint_names: tuple[str, ...] | list[str]) -> DensePoses:
    """Pivot a ``poses3d`` table to arrays over the given joint order (other joints are ignored).

    Raises:
        ValueError: none of ``joint_names`` occurs in the table while it has rows.
    """
    names = tuple(joint_names)
    codes = name_codes(poses["joint"], names)
    keep = codes >= 0
    rows, c = poses[keep], codes[keep]
    if len(poses) and not len(rows):
        raise ValueError(f"poses3d: no row has a joint in {list(names)[:5]}...; found {sorted(poses['joint'].unique())[:5]}")
    keys = rows[["frame", "person_id"]].to_numpy(dtype=np.int64)
    if len(keys) == 0:
        z = np.zeros(0, dtype=np.int64)
        return DensePoses(z, z, np.zeros((0, len(names), 3)), np.zeros((0, len(names)), bool), names)
    uniq, r = unique_rows(keys)
    X = np.full((len(uniq), len(names), 3), np.nan)
    valid = np.zeros((len(uniq), len(names)), bool)
    X[r, c] = rows[["x_m", "y_m", "z_m"]].to_numpy()
    valid[r, c] = rows["valid"].to_numpy(bool)
    X[~valid] = np.nan
    return DensePoses(uniq[:, 0], uniq[:, 1], X, valid, names)
