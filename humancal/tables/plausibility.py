"""Plausibility checks of canonical tables (used by the pipeline's asset checks and by readers).

Each check returns a :class:`CheckReport` rather than raising: the caller decides whether a failed
check blocks downstream work. A check that had nothing to examine (no cameras, no known focal length) does not
pass: its report says ``"not checked: <why>"`` with ``checked == 0`` (:attr:`CheckReport.not_checked`), so that
the caller can show a warning instead of a green mark.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.camera import cameras_from_table

__all__ = [
    "CheckReport",
    "check_detections_plausible",
    "check_cameras_valid",
    "check_focal_plausible",
    "check_rig_geometry",
    "check_body_size",
    "check_views_agree",
]


@dataclass(frozen=True)
class CheckReport:
    """Outcome of one check: pass/fail, a one-line description, and figures worth showing.

    Attributes:
        passed: the check ran on something and found nothing wrong.
        description: one line; ``"not checked: <why>"`` when there was nothing to check.
        figures: numbers worth showing beside the outcome.
        checked: how many items (rows, cameras, focal lengths) were examined; 0: nothing was checked, and
            ``passed`` is False.
    """

    passed: bool
    description: str
    figures: dict[str, float] = field(default_factory=dict)
    checked: int | None = None

    def __post_init__(self) -> None:
        if self.checked == 0 and self.passed:
            raise ValueError(f"CheckReport: a check that examined nothing cannot pass ({self.description!r})")

    @property
    def not_checked(self) -> bool:
        """True when there was nothing to check (the outcome says nothing about the data)."""
        return self.checked == 0

    @classmethod
    def nothing_to_check(cls, why: str, figures: dict[str, float] | None = None) -> CheckReport:
        """The report of a check that had nothing to examine: not passed, ``"not checked: <why>"``."""
        return cls(False, f"not checked: {why}", dict(figures or {}), checked=0)


def check_detections_plausible(detections: pd.DataFrame, views: pd.DataFrame, margin: float = 0.1) -> CheckReport:
    """Detections are finite, scores in [0, 1], and pixels within the image (plus ``margin`` of its size).

    Args:
        detections: canonical detections table.
        views: canonical views table (image size per view).
        margin: allowed overshoot beyond the image border, as a fraction of width/height.
    """
    if detections.empty:
        # an empty detections table is a broken input, not a clean one: fail (the pipeline blocks on it)
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
    return CheckReport(passed, text, figures, checked=len(x))


def check_cameras_valid(cameras: pd.DataFrame, tol: float = 1e-5) -> CheckReport:
    """Every camera has finite positive focal lengths, a principal point inside the image and a proper
    rotation (orthonormal, determinant +1: a right-handed camera frame). No camera at all: not checked."""
    if cameras.empty:
        return CheckReport.nothing_to_check("no cameras in the table", {"cameras": 0.0})
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
        return CheckReport(False, "; ".join(bad), figures, checked=len(cameras))
    return CheckReport(True, f"{len(cameras)} cameras: finite K, proper right-handed rotations", figures,
                       checked=len(cameras))


PLAUSIBLE_HFOV_DEG = (10.0, 140.0)
"""Horizontal fields of view of ordinary lenses (telephoto to wide angle, not fisheye), degrees."""


def check_focal_plausible(cameras: pd.DataFrame, hfov_deg: tuple[float, float] = PLAUSIBLE_HFOV_DEG) -> CheckReport:
    """Every focal length (``fx_px``, ``fy_px`` of a ``cameras`` or ``intrinsics`` table) gives a horizontal
    field of view inside ``hfov_deg`` for its image width, and fx, fy agree within 20 %. Views whose focal is
    not known yet (NaN, e.g. deferred intrinsics) are skipped and counted; when no focal is known (or the table
    is empty) the report is "not checked"."""
    bad, fovs, unknown = [], [], 0
    for r in cameras.itertuples(index=False):
        if not (np.isfinite(r.fx_px) and np.isfinite(r.fy_px)):
            unknown += 1
            continue
        if r.fx_px <= 0 or r.fy_px <= 0:
            bad.append(f"view {r.view}: focal {r.fx_px:.0f}/{r.fy_px:.0f} px not positive")
            continue
        fov = float(np.degrees(2.0 * np.arctan(0.5 * r.width_px / r.fx_px)))
        fovs.append(fov)
        if not hfov_deg[0] <= fov <= hfov_deg[1]:
            bad.append(f"view {r.view}: focal {r.fx_px:.0f} px gives a {fov:.1f} deg horizontal field of view "
                       f"for a {r.width_px} px wide image (plausible: {hfov_deg[0]:.0f}-{hfov_deg[1]:.0f} deg)")
        if abs(np.log(r.fx_px / r.fy_px)) > np.log(1.2):
            bad.append(f"view {r.view}: fx {r.fx_px:.0f} px and fy {r.fy_px:.0f} px differ by more than 20 %")
    figures = {"views": float(len(cameras)), "unknown_focal_views": float(unknown)}
    if fovs:
        figures.update(min_hfov_deg=min(fovs), max_hfov_deg=max(fovs))
    known = len(cameras) - unknown
    if bad:
        return CheckReport(False, "; ".join(bad), figures, checked=known)
    if known == 0:
        why = "no view in the table" if len(cameras) == 0 else f"the focal length of all {unknown} views is not known"
        return CheckReport.nothing_to_check(why, figures)
    note = f" ({unknown} not known yet)" if unknown else ""
    return CheckReport(True, f"{known} focal lengths give plausible fields of view{note}", figures, checked=known)


def check_rig_geometry(cameras: pd.DataFrame, people_floor_m: np.ndarray, min_in_view: float = 0.5, *,
                       floor_known: bool = True) -> CheckReport:
    """The calibrated rig makes physical sense in its world frame (Z up, floor z = 0, metres).

    * above the floor: every camera centre has z > 0 (only when ``floor_known``);
    * looking at the people: at least ``min_in_view`` of the people's positions are in front of every camera
      and project inside its image. With ``floor_known`` they are floor points (N, 3) raised to 1 m, the middle
      of a body; without (cameras in camera 0's frame, no floor found) they are the people's own positions
      (e.g. hip midpoints) and are used as given.

    The right-handedness of the camera frames is :func:`check_cameras_valid`'s. No camera at all: not checked.
    """
    if cameras.empty:
        return CheckReport.nothing_to_check("no cameras in the table", {})
    points = np.asarray(people_floor_m, dtype=np.float64).reshape(-1, 3)
    if floor_known:
        points = points + np.array([0.0, 0.0, 1.0])
    bad, heights, seen = [], [], []
    for v, cam in enumerate(cameras_from_table(cameras)):
        height = float(cam.center_world_m[2])
        heights.append(height)
        if floor_known and not height > 0:
            bad.append(f"view {v}: camera centre {height:.2f} m is not above the floor")
        if len(points):
            cam_pts = points @ cam.R_cam_from_world.T + cam.t_cam_from_world_m
            z = cam_pts[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = cam_pts[:, :2] / z[:, None] @ np.diag([cam.K[0, 0], cam.K[1, 1]]) + cam.K[:2, 2]
            inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width_px) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height_px)
            seen.append(float(inside.mean()))
            if inside.mean() < min_in_view:
                bad.append(f"view {v}: only {100 * inside.mean():.0f} % of the people are in front of the camera "
                           f"and inside its image (need {100 * min_in_view:.0f} %)")
    figures = {"min_camera_height_m": min(heights) if heights and floor_known else float("nan")}
    if seen:
        figures["min_people_in_view_fraction"] = min(seen)
    if not len(points):
        bad.append("no people positions to check the cameras' viewing directions against")
    if bad:
        return CheckReport(False, "; ".join(bad), figures, checked=len(heights))
    where = "above the floor" if floor_known else "(no floor found: heights not checked)"
    return CheckReport(True, f"{len(heights)} cameras {where}, each seeing most of the people", figures,
                       checked=len(heights))


def check_body_size(body_size_ratio: float, allowed: tuple[float, float] = (0.8, 1.25)) -> CheckReport:
    """The people triangulated with the calibrated cameras have the size the lifter gives them.

    ``body_size_ratio`` is :attr:`humancal.calibration.ExtrinsicsDiagnostics.body_size_ratio` (triangulated over
    lifted limb lengths, median over the matched people). A consistent rig gives about 1 (the bundle adjustment
    takes the metric scale from the lifted sizes); outside ``allowed`` the cameras and the people disagree, which
    a low reprojection error does not rule out (a rig six times too large fitted the detections of a synthetic
    scene to 1.5 px). NaN (no matched limb): not checked.
    """
    figures = {"body_size_ratio": float(body_size_ratio)}
    if not np.isfinite(body_size_ratio):
        return CheckReport.nothing_to_check("no matched person with measurable limbs", figures)
    low, high = allowed
    if not low <= body_size_ratio <= high:
        return CheckReport(False, f"the people triangulated with these cameras are {body_size_ratio:.2f} times the "
                                  f"size the lifter gives them (allowed {low}-{high}): the cameras are wrong, or the "
                                  "detections are not what they were declared (skeleton, image size)",
                           figures, checked=1)
    return CheckReport(True, f"the triangulated people are {body_size_ratio:.2f} times their lifted size", figures,
                       checked=1)


def _view_label(v: int, names) -> str:
    return f"view {v} ({names[v]})" if names is not None and v < len(names) else f"view {v}"


def _untrusted(row, names) -> str | None:
    """Why one view of a calibration's per-view table is not to be trusted (None: it is)."""
    label = _view_label(int(row.view), names)
    if row.bundle_status == "focal_at_bound":
        return (f"{label}: its focal length ended at the end of the plausible range ({row.focal_px:.0f} px): the "
                "people do not determine it")
    if row.bundle_status in ("behind_camera", "no_inliers"):
        return f"{label}: the bundle adjustment ended with {row.bundle_status.replace('_', ' ')}"
    if row.agreement == "disagrees":
        return f"{label} disagrees with the other views: {row.agreement_reason}"
    return None


def check_views_agree(per_view: pd.DataFrame, view_names=None) -> CheckReport:
    """Every view of a calibration agrees with the people the other views triangulate
    (:func:`humancal.calibration.view_agreement.view_agreement`) and its focal length is not at a bound of its range
    (how well the focal lengths are determined is the ``focal_constrained`` check's).

    Args:
        per_view: :attr:`humancal.calibration.ExtrinsicsDiagnostics.per_view` (columns ``view``, ``focal_px``,
            ``focal_rel_std``, ``bundle_status``, ``agreement``, ``agreement_reason``).
        view_names: the views' names in view order, for the message (None: numbers only).

    Returns:
        A failed report names every view not to trust, the figure and the way out.
    """
    if per_view.empty:
        return CheckReport.nothing_to_check("no view")
    problems = [p for p in (_untrusted(r, view_names) for r in per_view.itertuples()) if p]
    unchecked = per_view.loc[per_view["agreement"] == "unchecked", "view"].astype(int).tolist()
    figures = {"views_disagreeing": float((per_view["agreement"] == "disagrees").sum()),
               "views_unchecked": float(len(unchecked)),
               "max_loo_error_sigma": float(np.nanmax(per_view["loo_error_sigma"])) if per_view[
                   "loo_error_sigma"].notna().any() else float("nan"),
               "max_focal_rel_std": float(per_view["focal_rel_std"].replace(np.inf, np.nan).max())}
    if problems:
        return CheckReport(False, "; ".join(problems) + ". Leave the view out (--drop-view when adding the capture, "
                           "drop_views in its datasets entry), film people moving through the shared field of view "
                           "for longer, or give its known camera (--cameras with --known-views)", figures,
                           checked=len(per_view))
    note = (f"; {', '.join(_view_label(v, view_names) for v in unchecked)} could not be compared with two others"
            if unchecked else "")
    return CheckReport(True, f"all {len(per_view)} views agree with the people the others place{note}", figures,
                       checked=len(per_view))
