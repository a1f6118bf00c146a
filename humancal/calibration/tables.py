"""The calibration stage's results as canonical tables (``humancal.tables.schemas``): ``intrinsics`` and back."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from humancal.calibration.intrinsics import IntrinsicsEstimate
from humancal.camera import intrinsic_matrices, sorted_views

__all__ = ["intrinsics_to_table", "intrinsics_from_table"]


def intrinsics_to_table(sequence: str, estimates: Sequence[IntrinsicsEstimate]) -> pd.DataFrame:
    """One ``intrinsics`` row per view (focal NaN where ``status == "no_upright"``)."""
    return pd.DataFrame(
        {
            "sequence": sequence,
            "view": [e.view for e in estimates],
            "fx_px": [e.K[0, 0] for e in estimates],
            "fy_px": [e.K[1, 1] for e in estimates],
            "cx_px": [e.K[0, 2] for e in estimates],
            "cy_px": [e.K[1, 2] for e in estimates],
            "width_px": [e.width_px for e in estimates],
            "height_px": [e.height_px for e in estimates],
            "status": [e.status for e in estimates],
            "focal_rel_uncertainty": [e.focal_rel_uncertainty for e in estimates],
            "num_candidates": [e.num_candidates for e in estimates],
            "num_inliers": [e.num_inliers for e in estimates],
            "vanishing_x_px": [e.vanishing_point_px[0] for e in estimates],
            "vanishing_y_px": [e.vanishing_point_px[1] for e in estimates],
            "up_x": [e.up_cam[0] for e in estimates],
            "up_y": [e.up_cam[1] for e in estimates],
            "up_z": [e.up_cam[2] for e in estimates],
            "tilt_deg": [e.tilt_deg for e in estimates],
            "roll_deg": [e.roll_deg for e in estimates],
            "camera_height_m": [e.camera_height_m for e in estimates],
            "vp_rms_px": [e.vp_rms_px for e in estimates],
            "rms_px": [e.rms_px for e in estimates],
        }
    )


def intrinsics_from_table(table: pd.DataFrame) -> list[IntrinsicsEstimate]:
    """The per-view estimates of an ``intrinsics`` table, in view order.

    Raises:
        ValueError: the views are not 0..V-1, each once.
    """
    rows = sorted_views(table, "intrinsics")
    Ks = intrinsic_matrices(rows["fx_px"], rows["fy_px"], rows["cx_px"], rows["cy_px"])
    out = []
    for K, r in zip(Ks, rows.itertuples(index=False)):
        out.append(IntrinsicsEstimate(
            view=int(r.view), K=K, width_px=int(r.width_px), height_px=int(r.height_px), status=str(r.status),
            focal_rel_uncertainty=float(r.focal_rel_uncertainty), num_candidates=int(r.num_candidates),
            num_inliers=int(r.num_inliers), vanishing_point_px=np.array([r.vanishing_x_px, r.vanishing_y_px]),
            up_cam=np.array([r.up_x, r.up_y, r.up_z]), tilt_deg=float(r.tilt_deg), roll_deg=float(r.roll_deg),
            camera_height_m=float(r.camera_height_m), vp_rms_px=float(r.vp_rms_px), rms_px=float(r.rms_px),
        ))
    return out
