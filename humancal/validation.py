"""Plausibility checks of canonical tables (used by the pipeline's asset checks and by readers).

Each check returns a :class:`CheckReport` rather than raising: the caller decides whether a failed
check blocks downstream work.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.camera import cameras_from_table

__all__ = ["CheckReport", "check_detections_plausible", "check_cameras_valid"]


@dataclass(frozen=True)
class CheckReport:
    """Outcome of one check: pass/fail, a one-line description, and figures worth showing."""

    passed: bool
    description: str
    figures: dict[str, float] = field(default_factory=dict)


def check_detections_plausible(detections: pd.DataFrame, views: pd.DataFrame, margin: float = 0.1) -> CheckReport:
    """Detections are finite, scores in [0, 1], and pixels within the image (plus ``margin`` of its size).

    Args:
        detections: canonical detections table.
        views: canonical views table (image size per view).
        margin: allowed overshoot beyond the image border, as a fraction of width/height.
    """
    if detections.empty:
        return CheckReport(False, "no detections at all", {"rows": 0.0})
    size = views.set_index("view")[["width_px", "height_px"]]
    unknown = sorted(set(detections["view"].unique()) - set(size.index))
    if unknown:
        return CheckReport(False, f"detections in views {unknown} that have no image size", {})
    w = size["width_px"].reindex(detections["view"]).to_numpy(float)
    h = size["height_px"].reindex(detections["view"]).to_numpy(float)
    x, y, s = (detections[c].to_numpy(float) for c in ("x_px", "y_px", "score"))
    finite = np.isfinite(x) & np.isfinite(y) & np.isfinite(s)
    inside = (x >= -margin * w) & (x <= (1 + margin) * w) & (y >= -margin * h) & (y <= (1 + margin) * h)
    score_ok = (s >= 0) & (s <= 1)
    figures = {
        "rows": float(len(x)),
        "non_finite": float((~finite).sum()),
        "outside_image": float((~inside & finite).sum()),
        "score_out_of_range": float((~score_ok & finite).sum()),
    }
    passed = figures["non_finite"] == 0 and figures["outside_image"] == 0 and figures["score_out_of_range"] == 0
    text = "all detections finite, inside the image and scored in [0, 1]" if passed else (
        f"{int(figures['non_finite'])} non-finite, {int(figures['outside_image'])} outside the image "
        f"(margin {margin:.0%}), {int(figures['score_out_of_range'])} scores outside [0, 1]"
    )
    return CheckReport(passed, text, figures)


def check_cameras_valid(cameras: pd.DataFrame, tol: float = 1e-5) -> CheckReport:
    """Every camera has finite positive focal lengths, a principal point inside the image and a proper
    rotation (orthonormal, determinant +1: a right-handed camera frame)."""
    worst_orth, worst_det, bad = 0.0, 0.0, []
    for v, cam in enumerate(cameras_from_table(cameras)):
        K, R = cam.K, cam.R_cam_from_world
        orth = float(np.abs(R @ R.T - np.eye(3)).max())
        det = float(np.linalg.det(R))
        worst_orth, worst_det = max(worst_orth, orth), max(worst_det, abs(det - 1.0))
        if not (np.isfinite(K).all() and K[0, 0] > 0 and K[1, 1] > 0):
            bad.append(f"view {v}: focal not finite/positive")
        if not (0 <= K[0, 2] <= cam.width_px and 0 <= K[1, 2] <= cam.height_px):
            bad.append(f"view {v}: principal point outside the image")
        if orth > tol or abs(det - 1.0) > tol:
            bad.append(f"view {v}: rotation not proper (|RR^T-I|={orth:.1e}, det={det:.6f})")
        if not np.isfinite(cam.t_cam_from_world_m).all():
            bad.append(f"view {v}: translation not finite")
    figures = {"cameras": float(len(cameras)), "max_orthonormality_error": worst_orth, "max_det_error": worst_det}
    if bad:
        return CheckReport(False, "; ".join(bad), figures)
    return CheckReport(True, f"{len(cameras)} cameras: finite K, proper right-handed rotations", figures)
