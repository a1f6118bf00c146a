"""Does each view agree with the others? Every camera scored by the people triangulated *without* it.

A calibration can end in a rig where one camera is wrong and the others moved to meet it halfway: the bundle
adjustment's own residuals then look fine, since the wrong camera took part in placing the people it is judged
by. Here each view ``v`` is judged by people it did not help place:

* **leave-one-view-out reprojection**: the keypoints of every cross-view group (one person in one frame) are
  triangulated from the group's *other* views, projected into ``v`` and compared with ``v``'s detection of that
  group; the median error in units of the keypoint std (2 % of the person's image extent, at least 1 px, as the
  bundle adjustment measures it) is about 1.5 for a right camera and 5-30 for a wrong one;
* **explained detections**: every person of a sample of frames (``people``: clusters of the association, one per
  person and frame) is triangulated without ``v``; of ``v``'s detections (8 or more confident joints) in those
  frames, the fraction that lie within ``match_sigma`` (median joint error) of some such person. A wrong camera
  sees its people where the others put nobody (measured on seated 20-frame captures: 0.0-0.5 for views 45-600 %
  off in focal, 0.73-1.0 for right ones); unlike the first figure it also catches a wrong camera whose few groups
  were formed with the wrong people (they agree with it, the rest of its detections do not). The bundle
  adjustment's groups cannot serve here: they are a spread of a few hundred, so most frames have some of their
  people in no group;
* **cheirality**: the fraction of the people triangulated without ``v`` that lie behind it.

A view that cannot be compared (fewer than two other views share its groups, as in every two-view rig) is
``"unchecked"``, never ``"ok"``.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.camera import Camera, CameraRig
from humancal.config import Config, at_least, in_range, positive
from humancal.geometry.triangulation import triangulate_dlt
from humancal.keypoints import NUM_JOINTS
from humancal.tables.detections import DenseDetections

__all__ = ["AgreementConfig", "VIEW_VERDICTS", "view_agreement", "groups_by_view", "person_clusters",
           "agreement_with_people", "isolate_disagreeing_views"]

VIEW_VERDICTS = ("ok", "disagrees", "unchecked")
"""What :func:`view_agreement` says of a view: agrees with the others, disagrees, or could not be compared."""


@dataclass(frozen=True)
class AgreementConfig(Config):
    """Thresholds of :func:`view_agreement`.

    Attributes:
        min_score: keypoints under this 2D confidence are not used.
        max_loo_sigma: a view whose median leave-one-view-out error exceeds this many keypoint stds disagrees.
        min_explained: a view explaining a smaller fraction of its detections disagrees.
        max_behind: a view with a larger fraction of the others' people behind it disagrees.
        match_sigma: a detection is explained by a person whose projection is within this many keypoint stds of
            it (median over its joints).
        min_joints: detections with fewer confident joints are not counted by the explained fraction.
        min_compared: a view needs at least this many compared keypoints (and detections) to be judged.
    """

    min_score: float = field(default=0.2, metadata=in_range(0, 1))
    max_loo_sigma: float = field(default=3.0, metadata=positive())
    min_explained: float = field(default=0.6, metadata=in_range(0, 1))
    max_behind: float = field(default=0.1, metadata=in_range(0, 1))
    match_sigma: float = field(default=5.0, metadata=positive())
    min_joints: int = field(default=8, metadata=in_range(1, NUM_JOINTS, integer=True))
    min_compared: int = field(default=30, metadata=at_least(1, integer=True))


def groups_by_view(groups: Sequence[np.ndarray], view: np.ndarray, num_views: int) -> np.ndarray:
    """(G, V) detection row of each group in each view, -1 where the group has none.

    Args:
        groups: G arrays of detection rows (one person in one frame, at most one detection per view).
        view: (D,) view of every detection row.
        num_views: V.
    """
    table = np.full((len(groups), num_views), -1, dtype=np.int64)
    for g, rows in enumerate(groups):
        table[g, view[rows]] = rows
    return table


def view_agreement(
    cameras: CameraRig,
    detections: DenseDetections,
    groups: Sequence[np.ndarray],
    config: AgreementConfig | None = None,
    reference_views: Sequence[int] | None = None,
    people: Sequence[np.ndarray] | None = None,
) -> pd.DataFrame:
    """Score every view against the people triangulated without it (see the module docstring).

    Args:
        cameras: the rig of V cameras, one per view (pinholes: undistort the detections first if the lenses distort).
        detections: the detections the groups index (rows).
        groups: cross-view groups, each an array of detection rows of one person in one frame.
        config: thresholds; defaults to :class:`AgreementConfig`.
        reference_views: the views whose cameras place the people a view is judged by (default: all); a view
            outside them is judged by all of them.
        people: every person of a sample of frames, as arrays of detection rows (one person in one frame), for the
            explained fraction (None: not scored, NaN).

    Returns:
        One row per view: ``view``, ``compared`` (keypoints compared), ``loo_median_px``, ``loo_median_sigma``,
        ``explained_fraction`` (NaN when no detection could be compared), ``behind_fraction``, ``verdict`` (one
        of :data:`VIEW_VERDICTS`) and ``reason`` (empty for ``"ok"``).
    """
    config = config or AgreementConfig()
    V = len(cameras)
    table = groups_by_view(groups, detections.view, V)
    crowd = groups_by_view(people or [], detections.view, V)
    crowd_frame = np.array([detections.frame[rows[0]] for rows in people or []], dtype=np.int64)
    reference = list(range(V)) if reference_views is None else sorted(int(v) for v in reference_views)
    rows = [_score_view(v, [u for u in reference if u != v], cameras, detections, table, (crowd, crowd_frame),
                        config) for v in range(V)]
    return pd.DataFrame(rows)


def _keypoint_sigma_px(keypoints_px: np.ndarray) -> np.ndarray:
    """(N,) keypoint std of each detection ((N, 23, 2)): 2 % of its largest distance from its keypoints' mean,
    at least 1 px (the bundle adjustment's unit)."""
    with np.errstate(invalid="ignore"):
        size = np.nanmax(np.linalg.norm(keypoints_px - np.nanmean(keypoints_px, 1, keepdims=True), axis=-1), axis=1)
    return np.maximum(0.02 * np.nan_to_num(size), 1.0)


def _triangulate(others: list[int], cameras: CameraRig, detections: DenseDetections, table: np.ndarray,
                min_score: float):
    """(G, 23, 3) the groups' keypoints triangulated from their detections in ``others`` (NaN where fewer than
    two confident observations)."""
    G = len(table)
    if len(others) < 2:
        return np.full((G, NUM_JOINTS, 3), np.nan)
    points = np.full((len(others), G * NUM_JOINTS, 2), np.nan)
    weights = np.zeros((len(others), G * NUM_JOINTS))
    for k, u in enumerate(others):
        present = table[:, u] >= 0
        rows = table[present, u]
        scores = detections.scores[rows]
        index = (np.flatnonzero(present)[:, None] * NUM_JOINTS + np.arange(NUM_JOINTS)).reshape(-1)
        points[k, index] = detections.keypoints_px[rows].reshape(-1, 2)
        weights[k, index] = np.where(scores >= min_score, scores, 0.0).reshape(-1)
    X, _ = triangulate_dlt(CameraRig.from_cameras([cameras[u] for u in others]), points, weights)
    return X.reshape(G, NUM_JOINTS, 3)


def _project(camera: Camera, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of (..., 3) world points: (..., 2) pixels (NaN behind the camera) and (..., ) depths."""
    X_cam = X @ camera.R_cam_from_world.T + camera.t_cam_from_world_m
    depth = X_cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = X_cam[..., :2] / depth[..., None] @ camera.K[:2, :2].T + camera.K[:2, 2]
    return np.where((depth > 0)[..., None], uv, np.nan), depth


def _score_view(v, others, cameras, detections, table, crowd, config: AgreementConfig) -> dict:
    X = _triangulate(others, cameras, detections, table, config.min_score)
    uv, depth = _project(cameras[v], X)
    # leave-one-view-out reprojection of the groups v belongs to
    mine = np.flatnonzero(table[:, v] >= 0)
    rows = table[mine, v]
    observed = np.where((detections.scores[rows] >= config.min_score)[..., None], detections.keypoints_px[rows],
                        np.nan)
    sigma = _keypoint_sigma_px(detections.keypoints_px[rows])
    error_px = np.linalg.norm(uv[mine] - observed, axis=-1)  # (n, 23)
    finite = np.isfinite(error_px)
    compared = int(finite.sum())
    loo_px = float(np.median(error_px[finite])) if compared else float("nan")
    loo_sigma = float(np.median((error_px / sigma[:, None])[finite])) if compared else float("nan")
    placed = np.isfinite(depth)
    behind = float(np.mean(depth[placed] <= 0)) if placed.any() else float("nan")
    people_table, people_frame = crowd
    people_uv, _ = _project(cameras[v], _triangulate(others, cameras, detections, people_table, config.min_score))
    explained, counted = _explained_fraction(v, people_uv, detections, people_frame, config)
    people_loo = _loo_median_sigma(people_uv, people_table[:, v], detections, config)
    verdict, reason = _verdict(compared, counted, loo_sigma, explained, behind, config)
    return {"view": v, "compared": compared, "loo_median_px": loo_px, "loo_median_sigma": loo_sigma,
            "people_loo_sigma": people_loo, "explained_fraction": explained, "behind_fraction": behind,
            "verdict": verdict, "reason": reason}


def _loo_median_sigma(uv, rows_of_v, detections, config) -> float:
    """Median leave-one-view-out error (keypoint stds) of the detections ``rows_of_v`` ((G,), -1: none) against
    the projections ``uv`` ((G, 23, 2)) of their groups triangulated without the view."""
    mine = np.flatnonzero(rows_of_v >= 0)
    if len(mine) == 0:
        return float("nan")
    rows = rows_of_v[mine]
    observed = np.where((detections.scores[rows] >= config.min_score)[..., None], detections.keypoints_px[rows],
                        np.nan)
    error = np.linalg.norm(uv[mine] - observed, axis=-1) / _keypoint_sigma_px(detections.keypoints_px[rows])[:, None]
    error = error[np.isfinite(error)]
    return float(np.median(error)) if len(error) else float("nan")


def _explained_fraction(v, uv, detections: DenseDetections, frame_of_person, config) -> tuple[float, int]:
    """The fraction of ``v``'s confident detections in the people's frames that lie near a projected person
    ((P, 23, 2) ``uv``), and how many were counted (NaN, 0: none)."""
    usable = np.isfinite(uv).all(-1).sum(-1) >= config.min_joints  # people with enough projected joints
    if not usable.any():  # nobody placed by the other views (fewer than two of them): nothing to judge by
        return float("nan"), 0
    frames = np.unique(frame_of_person[usable])
    confident = detections.scores >= config.min_score
    candidates = np.flatnonzero((detections.view == v) & np.isin(detections.frame, frames)
                                & (confident.sum(1) >= config.min_joints))
    if len(candidates) == 0:
        return float("nan"), 0
    hits = np.zeros(len(candidates), bool)
    sigma = _keypoint_sigma_px(detections.keypoints_px[candidates])
    for f in frames:
        mine = np.flatnonzero(detections.frame[candidates] == f)
        projected = uv[usable & (frame_of_person == f)]  # (P, 23, 2)
        if len(mine) == 0 or len(projected) == 0:
            continue
        rows = candidates[mine]
        observed = np.where(confident[rows][..., None], detections.keypoints_px[rows], np.nan)  # (n, 23, 2)
        with warnings.catch_warnings():  # a person none of whose joints a detection has: NaN, not a match
            warnings.simplefilter("ignore", RuntimeWarning)
            error = np.nanmedian(np.linalg.norm(projected[None] - observed[:, None], axis=-1), axis=-1)  # (n, P)
        hits[mine] = (np.nan_to_num(error, nan=np.inf) < config.match_sigma * sigma[mine, None]).any(1)
    return float(hits.mean()), int(len(candidates))


def _verdict(compared, counted, loo_sigma, explained, behind, config) -> tuple[str, str]:
    """The verdict on one view from the figures it has enough data for (``"unchecked"`` when none)."""
    has_loo = compared >= config.min_compared
    has_explained = counted >= max(3, config.min_compared // 10)
    if not (has_loo or has_explained):
        return "unchecked", (f"too few of its keypoints seen by two other views ({compared}): it cannot be checked "
                             "against them")
    reasons = []
    if has_loo and loo_sigma > config.max_loo_sigma:
        reasons.append(f"its keypoints reproject {loo_sigma:.1f} stds from the people the other views place "
                       f"(at most {config.max_loo_sigma:g})")
    if has_explained and explained < config.min_explained:
        reasons.append(f"only {100 * explained:.0f} % of its detections lie near a person the other views place "
                       f"(at least {100 * config.min_explained:.0f} %)")
    if np.isfinite(behind) and behind > config.max_behind:
        reasons.append(f"{100 * behind:.0f} % of the others' people lie behind it")
    return ("disagrees", "; ".join(reasons)) if reasons else ("ok", "")


def person_clusters(detections: DenseDetections, person_id: np.ndarray, max_frames: int = 60) -> list[np.ndarray]:
    """One array of detection rows per person and frame seen in two views or more, in at most ``max_frames``
    frames spread evenly (the association's people, as :func:`view_agreement` groups).

    Args:
        detections: D detections.
        person_id: (D,) person of each detection (-1: none).
        max_frames: frames used at most.
    """
    person_id = np.asarray(person_id, dtype=np.int64)
    frames = np.unique(detections.frame[person_id >= 0])
    if len(frames) > max_frames:
        frames = frames[np.linspace(0, len(frames) - 1, max_frames).round().astype(int)]
    rows = np.flatnonzero((person_id >= 0) & np.isin(detections.frame, frames))
    rows = rows[np.lexsort((detections.view[rows], person_id[rows], detections.frame[rows]))]
    keys = np.c_[detections.frame[rows], person_id[rows]]
    cuts = np.flatnonzero((np.diff(keys, axis=0) != 0).any(1)) + 1
    return [c for c in np.split(rows, cuts) if len(np.unique(detections.view[c])) >= 2]


def agreement_with_people(cameras: CameraRig, detections: DenseDetections, person_id: np.ndarray,
                          config: AgreementConfig | None = None, max_frames: int = 60) -> pd.DataFrame:
    """:func:`view_agreement` of a rig judged by the people of an association (e.g. the cameras a body fit refined,
    with the association they were fitted to): its clusters are both the groups and the people."""
    clusters = person_clusters(detections, person_id, max_frames)
    return view_agreement(cameras, detections, clusters, config, people=clusters)


def _badness(row, config: AgreementConfig) -> float:
    """How far a view's figures are beyond the agreement's thresholds (> 1: beyond at least one)."""
    explained = row.explained_fraction if np.isfinite(row.explained_fraction) else 1.0
    return max(np.nan_to_num(row.loo_median_sigma) / config.max_loo_sigma,
               config.min_explained / max(explained, 1e-3),
               np.nan_to_num(row.behind_fraction) / max(config.max_behind, 1e-3))


def isolate_disagreeing_views(cameras: CameraRig, detections: DenseDetections, groups: Sequence[np.ndarray],
                              config: AgreementConfig, people: Sequence[np.ndarray] | None = None,
                              initial: pd.DataFrame | None = None) -> tuple[list[int], pd.DataFrame]:
    """The views to take out, worst first, until the others agree with each other (at least two stay): one wrong
    camera spoils the people the others are judged by, so the views are judged again without it each time.

    Args:
        cameras, detections, groups, config, people: as :func:`view_agreement`.
        initial: the agreement of every view with all the others, when the caller has it.

    Returns:
        (views taken out, the agreement of every view with the views left).
    """
    reference = list(range(len(cameras)))
    table = initial if initial is not None else view_agreement(cameras, detections, groups, config, people=people)
    out: list[int] = []
    while len(reference) > 2:
        inside = table[table["view"].isin(reference) & (table["verdict"] == "disagrees")]
        if inside.empty:
            break
        worst = int(inside.loc[inside.apply(_badness, axis=1, config=config).idxmax(), "view"])
        out.append(worst)
        reference.remove(worst)
        table = view_agreement(cameras, detections, groups, config, reference, people)
    return out, table
