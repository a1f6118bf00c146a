"""The lens of every view, chosen by held-out reprojection: pinhole, radial k1, or radial k1 and k2, and the
principal point at the image centre or estimated.

A richer lens always fits the groups it is adjusted on a little better; whether the capture supports it is a
question for groups it was not adjusted on. The groups are split by frame into two folds of alternating blocks of
consecutive frames (a block, not single frames: neighbouring frames repeat the same poses). For each candidate lens
the bundle adjustment is fitted on one fold, then the other fold's keypoints are found again with those cameras held
(:func:`~humancal.calibration.bundle.bundle_adjust` with ``adjust_cameras=False``): the score is that
fit's robust cost per held-out group, both its terms (keypoints reprojected, and the people's agreement with their
lifted poses: a pinhole fitted to a distorting lens reprojects nearly as well, by bending the rig and with it the
people, whose lifted shapes then disagree); the two folds' scores add up. Candidates go from simple to rich: radial terms first (``pinhole`` ->
``k1`` -> ``k1k2``), then the principal point on top of the chosen radial model; each richer candidate must lower
the held-out score by ``min_gain`` (a fraction) to be taken. The chosen lens is then adjusted on every group.

Ground truth plays no part in the choice. The detections are moved to the chosen lens's pinhole image once
(:func:`undistorted_detections`): the steps after it (the view check and repair, the world scale and floor) see a
pinhole camera with the estimated principal point, and the cameras carry the distortion out.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from humancal.calibration.bundle import BundleResult, bundle_adjust
from humancal.calibration.view_repair import check_and_repair_views
from humancal.camera import intrinsic_matrices
from humancal.camera.projection import undistort_points_px
from humancal.lifter.lifted import LiftedPoses
from humancal.tables.detections import DenseDetections

__all__ = ["LENS_MODELS", "LensChoice", "choose_lens", "frame_folds", "lens_fit", "lens_step", "undistorted_detections"]

LENS_MODELS = ("pinhole", "k1", "k1k2")
"""Radial lens models, simplest first."""

logger = logging.getLogger(__name__)

Fit = Callable[..., BundleResult]
"""``fit(groups, start, *, lens, principal_point, adjust_cameras=True) -> BundleResult``: the bundle adjustment of
the calibration on ``groups`` (list of detection-row arrays), started from ``start``'s cameras (and lens) with
``start.points_world_m`` as the groups' keypoints."""

@dataclass(frozen=True)
class LensChoice:
    """What :func:`choose_lens` compared and took.

    Attributes:
        model: the radial model taken (one of :data:`LENS_MODELS`).
        principal_point: ``"estimated"`` or ``"centre"`` (the one given).
        table: one row per candidate tried: ``model``, ``principal_point``, ``heldout_score`` (robust cost per held-out
            group, lower is better), ``heldout_median_sigma`` and ``taken``.
        reason: one line saying why (also logged).
        pinhole_views: views kept as pinholes under a richer model (their k1 undetermined or indistinguishable from
            0).
    """

    model: str
    principal_point: str
    table: pd.DataFrame
    reason: str
    pinhole_views: tuple[int, ...] = ()

    @property
    def pinhole_at_centre(self) -> bool:
        return self.model == "pinhole" and self.principal_point == "centre"


def frame_folds(frames: np.ndarray, blocks: int = 6) -> np.ndarray:
    """(G,) fold (0 or 1) of every group from its frame (G,): the sorted distinct frames cut into ``blocks`` runs of
    consecutive frames, alternately given to the two folds."""
    distinct = np.unique(frames)
    block = np.minimum((np.searchsorted(distinct, frames) * blocks) // max(len(distinct), 1), blocks - 1)
    return (block % 2).astype(int)


def _subset(ba: BundleResult, keep: np.ndarray) -> BundleResult:
    return replace(ba, points_world_m=ba.points_world_m[keep])


def _heldout(fit: Fit, start: BundleResult, groups: list[np.ndarray], folds: np.ndarray, lens: str,
             principal_point: bool) -> tuple[float, float]:
    """Held-out score of one candidate, fitted on each fold and scored on the other: the robust cost per group of
    the held-out groups with the cameras held (their reprojections and their agreement with the lifted poses),
    and the held-out detections' median reprojection error in keypoint stds."""
    costs, medians = [], []
    for held in (0, 1):
        train, test = np.flatnonzero(folds != held), np.flatnonzero(folds == held)
        fitted = fit([groups[i] for i in train], _subset(start, train), lens=lens, principal_point=principal_point)
        scored = fit([groups[i] for i in test], replace(fitted, points_world_m=start.points_world_m[test]),
                     lens=lens, principal_point=principal_point, adjust_cameras=False)
        costs.append(scored.cost)
        errors = scored.detection_error_sigma
        medians.append(float(np.nanmedian(errors)) if np.isfinite(errors).any() else np.nan)
    return float(sum(costs) / len(groups)), float(np.nanmean(medians))


def choose_lens(fit: Fit, ba: BundleResult, groups: list[np.ndarray], frames: np.ndarray, *, models=LENS_MODELS,
                principal_point: str = "auto", min_gain: float = 0.02, min_groups: int = 12,
                max_k1_std: float = 0.25, min_k1_sigma: float = 2.0) -> tuple[BundleResult, LensChoice]:
    """The lens the capture supports (see the module docstring), adjusted on every group.

    Args:
        fit: the calibration's bundle adjustment (:data:`Fit`).
        ba: the pinhole bundle adjustment on ``groups`` (its cameras and keypoints start every candidate).
        groups: G arrays of detection rows, one person in one frame each.
        frames: (G,) the frame of every group.
        models: the radial models to try, simplest first (``("pinhole",)``: radial distortion off; one richer
            model alone: taken without a comparison).
        principal_point: ``"auto"`` (tried on top of the chosen radial model), ``"centre"`` (kept as given) or
            ``"estimate"`` (always estimated).
        min_gain: relative decrease of the held-out score a richer candidate needs to be taken.
        min_groups: with fewer groups per fold, nothing richer than the given models' first is tried.
        max_k1_std, min_k1_sigma: a view whose k1 has a larger std (:attr:`BundleResult.lens_std`), or lies within
            ``min_k1_sigma`` stds of 0, is kept a pinhole (its radial terms held at 0) and the rest adjusted again.

    Returns:
        The bundle adjustment with the chosen lens (``ba`` itself for a pinhole at the centre), and the
        :class:`LensChoice`.
    """
    if principal_point not in ("auto", "centre", "estimate"):
        raise ValueError(f"principal_point must be 'auto', 'centre' or 'estimate', got {principal_point!r}")
    bad = [m for m in models if m not in LENS_MODELS]
    if bad or not models:
        raise ValueError(f"lens models must be among {LENS_MODELS}, got {list(models)}")
    folds = frame_folds(np.asarray(frames))
    rows: list[dict] = []
    enough = min(np.bincount(folds, minlength=2)) >= min_groups
    forced_pp = principal_point == "estimate"
    if len(models) == 1 and principal_point != "auto":
        model, pp_on = models[0], forced_pp
        reason = f"lens {model}, principal point {'estimated' if pp_on else 'at the centre'}: as configured"
    elif not enough:
        model, pp_on = models[0], forced_pp
        reason = (f"lens {model}: too few people in frames ({len(groups)} groups) to compare lenses on held-out "
                  "frames")
    else:
        best = None
        for model_try in models:
            score, median = _heldout(fit, ba, groups, folds, model_try, forced_pp)
            rows.append({"model": model_try, "principal_point": "estimated" if forced_pp else "centre",
                         "heldout_score": score, "heldout_median_sigma": median})
            if best is None or score < best[0] * (1.0 - min_gain):
                best = (score, model_try)
        model, pp_on = best[1], forced_pp
        if principal_point == "auto":
            score, median = _heldout(fit, ba, groups, folds, model, True)
            rows.append({"model": model, "principal_point": "estimated", "heldout_score": score,
                         "heldout_median_sigma": median})
            pp_on = score < best[0] * (1.0 - min_gain)
        scores = ", ".join(f"{r['model']}{'+pp' if r['principal_point'] == 'estimated' else ''} "
                           f"{r['heldout_score']:.3g}" for r in rows)
        reason = (f"lens {model}, principal point {'estimated' if pp_on else 'at the centre'}: held-out score "
                  f"{scores} (a richer lens needs {100 * min_gain:.0f} % less)")
    table = pd.DataFrame(rows, columns=["model", "principal_point", "heldout_score", "heldout_median_sigma"])
    table["taken"] = (table["model"] == model) & (table["principal_point"] == ("estimated" if pp_on else "centre"))
    if model == "pinhole" and not pp_on:
        logger.info("%s", reason)
        return ba, LensChoice(model, "centre", table, reason)
    fitted = fit(groups, ba, lens=model, principal_point=pp_on)
    k1, k1_std = fitted.distortion[:, 0], fitted.lens_std[:, 0]
    # a view's radial terms stay only where its data determine them and they differ from a pinhole's
    pinhole_views = np.flatnonzero(np.isfinite(k1_std) & ((k1_std > max_k1_std) | (np.abs(k1) < min_k1_sigma * k1_std)))
    if model != "pinhole" and len(pinhole_views):
        reason += (f"; views {pinhole_views.tolist()} kept as pinholes (k1 {np.round(k1[pinhole_views], 3).tolist()} "
                   f"+- {np.round(k1_std[pinhole_views], 3).tolist()}: not determined to {max_k1_std} or not "
                   f"{min_k1_sigma} stds from 0)")
        if len(pinhole_views) == len(k1) and not pp_on:
            logger.info("%s", reason)
            return ba, LensChoice("pinhole", "centre", table, reason, tuple(pinhole_views.tolist()))
        fitted = fit(groups, ba, lens=model, principal_point=pp_on, hold_more=tuple(pinhole_views.tolist()))
    logger.info("%s", reason)
    return fitted, LensChoice(model, "estimated" if pp_on else "centre", table, reason, tuple(pinhole_views.tolist()))


def lens_fit(detections: DenseDetections, lifted_cam: LiftedPoses, principal_point_px: np.ndarray,
             focal_bounds_px: np.ndarray, focal_prior_px: np.ndarray, focal_prior_rel_std: np.ndarray, config,
             hold_lens_views=()) -> Fit:
    """The calibration's bundle adjustment as a :data:`Fit`: the settings of ``config``
    (:class:`~humancal.calibration.ExtrinsicsConfig`), the focal priors and bounds, the lifted poses in camera
    frames (``lifted_cam``), the principal points given (V, 2, pixels) that the lens's offsets start from; the lens
    parameters of ``hold_lens_views`` (known cameras: their detections are already undistorted) stay zero, and the
    radial terms of a fit's ``hold_more`` views (kept pinholes; their principal points still move when estimated)."""
    pp = np.asarray(principal_point_px, dtype=np.float64)

    def fit(groups, start: BundleResult, *, lens: str, principal_point: bool, adjust_cameras: bool = True,
            hold_more=()):
        lens_start = np.zeros((len(pp), 4))
        if start.distortion is not None:
            lens_start[:, :2] = start.distortion[:, :2]
        if start.principal_point_px is not None:
            lens_start[:, 2:] = start.principal_point_px - pp
        held = sorted(hold_lens_views)
        lens_start[list(held)] = 0.0
        lens_start[list(hold_more), :2] = 0.0  # kept pinholes: radial terms held at 0, the principal point as chosen
        return bundle_adjust(
            detections, lifted_cam, groups, start.points_world_m, start.fx_px, start.fy_px, pp,
            start.R_cam_from_world, start.t_cam_from_world_m, square_pixels=config.square_pixels,
            focal_prior_px=focal_prior_px, focal_prior_rel_std=focal_prior_rel_std, shape_std_m=config.shape_std_m,
            group_scale_std=config.person_scale_std, focal_bounds_px=focal_bounds_px,
            max_iterations=config.bundle_iterations, lens=lens, principal_point=principal_point,
            lens_start=lens_start, hold_lens_views=held, hold_radial_views=tuple(hold_more),
            adjust_cameras=adjust_cameras)

    return fit


def undistorted_detections(detections: DenseDetections, K: np.ndarray, distortion: np.ndarray) -> DenseDetections:
    """The detections moved to each view's pinhole image: keypoints undistorted with the view's ``K`` (V, 3, 3)
    and OpenCV ``distortion`` (V, 5), and projected again with the same ``K`` (pixels); non-finite keypoints stay
    non-finite."""
    keypoints = detections.keypoints_px.copy()
    for v in range(len(K)):
        if np.any(distortion[v]):
            rows = np.flatnonzero(detections.view == v)
            moved = undistort_points_px(keypoints[rows].reshape(-1, 2), K[v], distortion[v])
            keypoints[rows] = moved.reshape(len(rows), -1, 2)
    return replace(detections, keypoints_px=keypoints)


def lens_step(ba, groups, detections, lifted_as_given, pp, bounds, f0, prior_rel, config, known_views, inputs,
               repair):
    """The calibration's lens step: the lens of every view (:func:`choose_lens`) on the checked rig's groups, and the
    views' agreement scored again in the chosen lens's pinhole images. A lens that puts a view that agreed out of
    agreement is not taken.

    Args:
        ba, groups: the checked rig's bundle adjustment and groups; detections, lifted_as_given: as the calibration
            has them; pp: (V, 2) principal points; bounds, f0, prior_rel: the focal bounds and priors; config:
            :class:`~humancal.calibration.ExtrinsicsConfig`; known_views: views whose lens stays a pinhole;
            inputs, repair: the view check's inputs and result (:mod:`.view_repair`).

    Returns:
        ``(ba, lens, distortion (V, 5), lens_std (V, 4): the std of k1, k2, cx_px, cy_px (NaN where not estimated),
        principal points (V, 2), detections, repair)``: the detections moved to
        the pinhole images of the lens, the repair's final agreement the one of the returned rig.
    """
    V = len(ba.fx_px)
    lifted = (lifted_as_given.in_camera_frame(intrinsic_matrices(ba.fx_px, ba.fx_px, pp[:, 0], pp[:, 1])[detections.view])
              if lifted_as_given.frame == "crop" else lifted_as_given)
    fit = lens_fit(detections, lifted, pp, bounds, f0, prior_rel, config, hold_lens_views=known_views)
    with_lens, lens = choose_lens(fit, ba, groups, detections.frame[[g[0] for g in groups]],
                                  models=config.lens_models, principal_point=config.principal_point,
                                  min_gain=config.lens_min_gain, max_k1_std=config.lens_max_k1_std,
                                  min_k1_sigma=config.lens_min_k1_sigma)
    if lens.pinhole_at_centre:
        return ba, lens, np.zeros((V, 5)), np.full((V, 4), np.nan), pp, detections, repair
    pp_lens = with_lens.principal_point_px.copy()
    seen = undistorted_detections(detections, intrinsic_matrices(with_lens.fx_px, with_lens.fy_px, pp_lens[:, 0], pp_lens[:, 1]), with_lens.distortion)
    _, _, scored = check_and_repair_views(with_lens, groups, replace(
        inputs, detections=seen, principal_points_px=pp_lens), repair=False)
    lost = (scored.final["verdict"] == "disagrees") & (repair.final["verdict"] != "disagrees")
    if lost.any():
        views = np.flatnonzero(lost.to_numpy()).tolist()
        reason = f"{lens.reason}; not taken: views {views} no longer agree with the others with it"
        logger.warning("lens: %s", reason)
        return ba, replace(lens, model="pinhole", principal_point="centre", reason=reason), \
            np.zeros((V, 5)), np.full((V, 4), np.nan), pp, detections, repair
    return (with_lens, lens, with_lens.distortion, with_lens.lens_std, pp_lens, seen,
            replace(repair, final=scored.final))
