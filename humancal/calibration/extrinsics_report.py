"""The tables :class:`~humancal.calibration.extrinsics_config.ExtrinsicsDiagnostics` reports: per view, per view
pair, and the matched groups (their columns are described there)."""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd

from humancal.tables.detections import DenseDetections

__all__ = ["group_table", "pair_table", "per_view_table"]

logger = logging.getLogger("humancal.calibration.extrinsics")


def per_view_table(ba, intrinsics, pairs, f_linear: np.ndarray, blind: np.ndarray, resected: np.ndarray,
                   distortion: np.ndarray, lens_std: np.ndarray, pp: np.ndarray, repair, config) -> pd.DataFrame:
    """One row per view: its focal lengths along the way and their status, its lens and principal point, its
    rotation edges and its agreement with the other views; a warning names the poorly constrained focal lengths.

    Args:
        ba: the final bundle adjustment (:class:`~humancal.calibration.bundle.BundleResult`).
        intrinsics: (V,) the single-view estimates.
        pairs: the pair rotations (their support counts the rotation edges).
        f_linear, blind, resected: (V,) the linear focal lengths, pixels; the views it could not see; those placed
            by a resection.
        distortion: (V, 5) the lens; lens_std: (V, 4) the std of k1, k2, cx_px, cy_px (NaN: not estimated, a pinhole
            or a centred principal point); pp: (V, 2) principal points, pixels.
        repair: the view agreement (:func:`~humancal.calibration.view_repair.check_and_repair_views`).
        config: the :class:`~humancal.calibration.extrinsics_config.ExtrinsicsConfig`.
    """
    V = len(intrinsics)
    edges = np.zeros(V, int)
    for p in pairs:
        if p.support >= config.min_pair_support:
            edges[[p.view_a, p.view_b]] += 1
    per_view = pd.DataFrame({
        "view": np.arange(V),
        "focal_single_view_px": [e.fx_px for e in intrinsics],
        "single_view_status": [e.status for e in intrinsics],
        "focal_linear_px": f_linear,
        "focal_px": ba.fx_px,
        "focal_rel_std": ba.focal_rel_std,
        "focal_status": np.where((ba.focal_rel_std <= config.max_focal_rel_std) & (ba.view_status == "ok"), "ok",
                                 "poorly_constrained"),
        "focal_source": np.where([e.status == "ok" for e in intrinsics], "single_view+bundle",
                                 np.where(resected, "resection+bundle",
                                          np.where(blind, "other_views+bundle", "linear+bundle"))),
        "bundle_status": ba.view_status,
        "k1": distortion[:, 0],
        "k1_std": lens_std[:, 0],
        "k2": distortion[:, 1],
        "cx_px": pp[:, 0],
        "cy_px": pp[:, 1],
        "cx_std_px": lens_std[:, 2],
        "cy_std_px": lens_std[:, 3],
        "reprojection_rms_px": ba.reprojection_rms_px,
        "rotation_edges": edges,
        "agreement": repair.final["verdict"].to_numpy(),
        "agreement_reason": repair.final["reason"].to_numpy(),
        "loo_error_sigma": repair.final["loo_median_sigma"].to_numpy(),
        "people_loo_sigma": repair.final["people_loo_sigma"].to_numpy(),
        "explained_fraction": repair.final["explained_fraction"].to_numpy(),
        "first_agreement": repair.first["verdict"].to_numpy(),
        "reregistered": np.isin(np.arange(V), repair.reregistered) & repair.kept,
    })
    bad = per_view[per_view["focal_status"] != "ok"]
    if len(bad):
        logger.warning("focal lengths of views %s are poorly constrained (relative std %s)", bad["view"].tolist(),
                       np.round(bad["focal_rel_std"].to_numpy(), 3).tolist())
    return per_view


def pair_table(pairs, residual_deg: np.ndarray) -> pd.DataFrame:
    """One row per view pair: ``view_a``, ``view_b``, ``support``, ``residual_deg``."""
    return pd.DataFrame({
        "view_a": [p.view_a for p in pairs], "view_b": [p.view_b for p in pairs],
        "support": [p.support for p in pairs], "residual_deg": residual_deg,
    })


def group_table(detections: DenseDetections, groups: list[np.ndarray]) -> pd.DataFrame:
    """The matched detections: ``frame``, ``view``, ``det_id``, ``group``."""
    rows = np.concatenate(groups)
    return pd.DataFrame({
        "frame": detections.frame[rows], "view": detections.view[rows], "det_id": detections.det_id[rows],
        "group": np.repeat(np.arange(len(groups)), [len(g) for g in groups]),
    })
