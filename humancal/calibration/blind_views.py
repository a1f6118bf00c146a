"""Views the linear focal + translation solve cannot see (a straight-down camera, a view whose pairs do not determine
its focal): which they are, and where they start the bundle adjustment from (a resection against the people placed
by the other views, or the other views' field of view with a translation that puts their people where the others
see them). Used by :func:`humancal.calibration.extrinsics.estimate_extrinsics`."""

from __future__ import annotations

import logging

import numpy as np

from humancal.calibration.translations import resect_focal_translation

logger = logging.getLogger(__name__)

__all__ = ["blind_views", "other_views_focal", "resection_pass", "translations_from_others"]


def resection_pass(groups, detections, lifted, roots_T, R, t, f, pp, bounds, views):
    """Re-estimate the focal and translation of ``views`` from the people placed by the other views.

    A resection is accepted only when its focal lies within the plausible ``bounds`` ((V, 2), pixels) and it and
    the translation are finite (``accepted``); the other views keep ``f`` and ``t``, as does a view whose
    resection fails numerically (a degenerate set of points).

    The linear solve sees a view's focal only through the spread of its people's depths, which vanishes for a
    camera looking straight down (all people at about the same depth) and is attenuated by depth noise;
    resection uses the perspective of the 3D keypoints instead.
    """
    view = detections.view
    Rt = np.transpose(R, (0, 2, 1))
    f_new, t_new = f.copy(), t.copy()
    accepted = np.zeros(len(f), bool)
    for v in views:
        X, x, w = [], [], []
        for g in groups:
            mine = g[view[g] == v]
            others = g[view[g] != v]
            if len(mine) != 1 or len(others) == 0:
                continue
            d = mine[0]
            world = np.mean([Rt[view[o]] @ (lifted.joints_cam_m[o] + roots_T[o] - t[view[o]]).T for o in others],
                            axis=0).T
            X.append(world)
            x.append(detections.keypoints_px[d])
            w.append(np.where(detections.scores[d] >= 0.3, detections.scores[d], 0.0))
        if len(X) < 3:
            continue
        try:
            fv, tv, _ = resect_focal_translation(np.concatenate(X), np.concatenate(x), np.concatenate(w), R[v],
                                                 pp[v])
        except np.linalg.LinAlgError as error:  # a degenerate point set: this view is simply not resected
            logger.info("view %d: resection failed (%s); it keeps its starting focal", v, error)
            continue
        if np.isfinite(fv) and bounds[v, 0] <= fv <= bounds[v, 1] and np.isfinite(tv).all():
            f_new[v], t_new[v] = fv, tv
            accepted[v] = True
    return f_new, t_new, accepted


def blind_views(f, sol, undetermined, bounds, diag, config) -> np.ndarray:
    """Views whose linear focal is no estimate: non-positive or non-finite in the last solve, at an end of the
    linear range (a clamp), outside the plausible field of view, or with a large data-only std."""
    lo, hi = config.focal_range_rel[0] * diag, config.focal_range_rel[1] * diag
    with np.errstate(invalid="ignore"):
        return (undetermined | ~np.isfinite(sol.focal_rel_std_data) | (sol.focal_rel_std_data > config.linear_max_rel_std)
                | (f <= lo * 1.01) | (f >= hi * 0.99) | (f < bounds[:, 0]) | (f > bounds[:, 1]))


def other_views_focal(f, blind, widths, f0, bounds) -> np.ndarray:
    """(V,) starting focal of every view from the median field of view (focal over image width) of the views that
    are not ``blind``; without any, the initial (single-view or typical) focal; inside the plausible bounds."""
    if (~blind).any():
        start = float(np.median(f[~blind] / widths[~blind])) * widths
    else:
        start = f0.astype(float)
    return np.clip(start, bounds[:, 0], bounds[:, 1])


def translations_from_others(groups, detections, lifted, roots_T, R, t, views) -> np.ndarray:
    """(V, 3) translations of ``views`` that put their people's roots (at their current focal) where the other
    views place them: per view the median over groups of ``T_cam - R X_root``; the other rows keep ``t``."""
    view = detections.view
    Rt = np.transpose(R, (0, 2, 1))
    t_new = t.copy()
    for v in views:
        offsets = []
        for g in groups:
            mine, others = g[view[g] == v], g[view[g] != v]
            if len(mine) != 1 or len(others) == 0 or not np.isfinite(roots_T[mine[0]]).all():
                continue
            world = [Rt[view[o]] @ (roots_T[o] - t[view[o]]) for o in others if np.isfinite(roots_T[o]).all()]
            if world:
                offsets.append(roots_T[mine[0]] - R[v] @ np.mean(world, axis=0))
        if offsets:
            t_new[v] = np.median(offsets, axis=0)
    return t_new
