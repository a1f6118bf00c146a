"""Which ground-truth person each 2D detection is: detections matched to projected ground-truth people.

For datasets that give 3D ground truth but not the identity of each detection (Shelf), and for the grouping
metrics of ``evaluation.detection_quality``, which states the protocol:

* Each ground-truth person is projected into each view with the ground-truth camera. A projected joint is
  *visible* when it lies in front of the camera and inside the image. A person-view *counts* when at least
  ``min_visible_fraction`` of its evaluated joints are visible.
* A detection and a projected person are *close* when they share at least ``min_common_joints`` joints (visible
  and detected) and the mean pixel distance over those is below ``threshold_fraction`` of the image diagonal.
* Per view and frame, detections are matched one-to-one to the counted person-views by
  ``scipy.optimize.linear_sum_assignment`` on the mean distance, among close pairs only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment

from humancal.camera import Camera, project_points
from humancal.tables import validate_table

__all__ = ["GroundTruthMatch", "match_ground_truth"]


@dataclass(frozen=True)
class GroundTruthMatch:
    """Per-item results of :func:`match_ground_truth`.

    Attributes:
        person_views: one row per (sequence, frame, view, person_id) of a projected ground-truth person with columns
            ``counted`` (bool, the person-view counts for recall), ``visible_joints``, ``det_id`` (matched detection,
            -1 if none), ``mean_error_px`` (NaN if unmatched).
        detections: one row per (sequence, frame, view, det_id) with ``matched_person`` (-1 if none),
            ``nearest_person`` (the closest ground-truth person among those it is close to, -1 if none) and
            ``fragment`` (close to some person but unmatched).
        joint_errors_px: one row per (sequence, frame, view, det_id, joint) of the matched pairs' common joints.
    """

    person_views: pd.DataFrame
    detections: pd.DataFrame
    joint_errors_px: pd.DataFrame


def match_ground_truth(
    detections: pd.DataFrame,
    gt_poses: pd.DataFrame,
    cameras: Sequence[Camera],
    *,
    joints: Sequence[str] | None = None,
    threshold_fraction: float = 0.05,
    min_visible_fraction: float = 0.5,
    min_common_joints: int = 1,
) -> GroundTruthMatch:
    """Match grouped 2D detections to projected ground-truth people (see the module docstring).

    Args:
        detections: canonical ``detections`` table (pixels); rows with score 0 count as undetected.
        gt_poses: canonical ``poses3d`` table (world, metres); rows with ``valid`` False are ignored.
        cameras: ground-truth cameras, indexed by ``view``.
        joints: joint names to evaluate; default: the names both tables use, in ground-truth order.
        threshold_fraction: closeness threshold as a fraction of the image diagonal.
        min_visible_fraction: fraction of evaluated joints that must be visible for a person-view to count.
        min_common_joints: fewest common joints for a detection to be close to a person.

    Returns:
        The matched person-views, the detections with their match, and the joint errors of matched pairs.

    Raises:
        ValueError: no shared joint names, views without a camera, or bad parameters.
        humancal.tables.TableError: a table does not match its schema.
    """
    detections = validate_table(detections, "detections", source="match_ground_truth detections")
    gt_poses = validate_table(gt_poses, "poses3d", source="match_ground_truth gt_poses")
    if not 0.0 < threshold_fraction:
        raise ValueError(f"threshold_fraction must be > 0, got {threshold_fraction}")
    if not 0.0 <= min_visible_fraction <= 1.0:
        raise ValueError(f"min_visible_fraction must lie in [0, 1], got {min_visible_fraction}")
    if min_common_joints < 1:
        raise ValueError(f"min_common_joints must be >= 1, got {min_common_joints}")
    if joints is None:
        det_names = set(detections["joint"].unique())
        joints = [j for j in dict.fromkeys(gt_poses["joint"]) if j in det_names]
    joints = list(joints)
    if not joints:
        raise ValueError(
            "match_ground_truth: the detections and the ground truth share no joint names "
            f"(ground truth has {sorted(gt_poses['joint'].unique())})"
        )
    views = sorted(detections["view"].unique().tolist())
    missing = [v for v in views if v >= len(cameras)]
    if missing:
        raise ValueError(f"match_ground_truth: detections name view(s) {missing} but only {len(cameras)} cameras given")
    jidx = {name: i for i, name in enumerate(joints)}

    # Plain numpy arrays grouped by image: pandas group objects are too slow for thousands of images.
    all_dets = detections[["sequence", "frame", "view", "det_id"]].drop_duplicates()
    ids_by_image = _group_rows(all_dets, ["sequence", "frame", "view"])
    det = detections[detections["joint"].isin(jidx) & (detections["score"] > 0)]
    det_by_image = _group_rows(det, ["sequence", "frame", "view"])
    det_id, det_joint = det["det_id"].to_numpy(), det["joint"].map(jidx).to_numpy()
    det_xy = det[["x_px", "y_px"]].to_numpy()
    all_det_id = all_dets["det_id"].to_numpy()
    gt = gt_poses[gt_poses["joint"].isin(jidx) & gt_poses["valid"]]
    gt_by_frame = _group_rows(gt, ["sequence", "frame"])
    gt_pid, gt_joint = gt["person_id"].to_numpy(), gt["joint"].map(jidx).to_numpy()
    gt_xyz = gt[["x_m", "y_m", "z_m"]].to_numpy()
    min_visible = max(1, int(np.ceil(min_visible_fraction * len(joints))))

    pv_rows, det_rows, err_rows = [], [], []
    for (seq, frame), rows in sorted(gt_by_frame.items()):
        pids = np.unique(gt_pid[rows])
        X = np.full((len(pids), len(joints), 3), np.nan)
        X[np.searchsorted(pids, gt_pid[rows]), gt_joint[rows]] = gt_xyz[rows]
        for view, cam in enumerate(cameras):
            gt_px, _ = project_points(cam, X)
            inside = (
                np.isfinite(gt_px).all(-1)
                & (gt_px[..., 0] >= 0)
                & (gt_px[..., 0] < cam.width_px)
                & (gt_px[..., 1] >= 0)
                & (gt_px[..., 1] < cam.height_px)
            )
            counted = inside.sum(-1) >= min_visible
            ids = np.unique(all_det_id[ids_by_image.get((seq, frame, view), [])])
            det_px = np.full((len(ids), len(joints), 2), np.nan)
            drows = det_by_image.get((seq, frame, view), [])
            det_px[np.searchsorted(ids, det_id[drows]), det_joint[drows]] = det_xy[drows]
            threshold_px = threshold_fraction * float(np.hypot(cam.width_px, cam.height_px))
            m = _match_image(gt_px, inside, counted, det_px, threshold_px, min_common_joints)
            for p, d in enumerate(m.person_det):
                if d >= 0:
                    err_rows.extend(
                        (seq, frame, view, int(ids[d]), joints[j], float(m.dist[p, d, j]))
                        for j in np.flatnonzero(m.common[p, d])
                    )
                pv_rows.append(
                    (
                        seq,
                        frame,
                        view,
                        int(pids[p]),
                        bool(counted[p]),
                        int(inside[p].sum()),
                        int(ids[d]) if d >= 0 else -1,
                        float(m.mean[p, d]) if d >= 0 else np.nan,
                    )
                )
            for d, det_id_d in enumerate(ids):
                matched = int(pids[m.det_person[d]]) if m.det_person[d] >= 0 else -1
                near = int(pids[m.nearest[d]]) if m.nearest[d] >= 0 else -1
                det_rows.append((seq, frame, view, int(det_id_d), matched, near, bool(near >= 0 and matched < 0)))
    # Detections in frames without any ground truth: neither matched nor fragments.
    for (seq, frame, view), rows in ids_by_image.items():
        if (seq, frame) not in gt_by_frame:
            det_rows.extend((seq, frame, view, int(d), -1, -1, False) for d in np.unique(all_det_id[rows]))

    person_views = pd.DataFrame(
        pv_rows,
        columns=["sequence", "frame", "view", "person_id", "counted", "visible_joints", "det_id", "mean_error_px"],
    )
    det_table = pd.DataFrame(
        det_rows, columns=["sequence", "frame", "view", "det_id", "matched_person", "nearest_person", "fragment"]
    )
    errors = pd.DataFrame(err_rows, columns=["sequence", "frame", "view", "det_id", "joint", "error_px"])
    return GroundTruthMatch(person_views, det_table, errors)




@dataclass(frozen=True)
class _ImageMatch:
    dist: np.ndarray  # (person, det, joint) pixel distance, NaN where the joint is not common
    common: np.ndarray  # (person, det, joint) visible in the projection and detected
    mean: np.ndarray  # (person, det) mean distance over common joints
    person_det: np.ndarray  # (person,) matched detection, -1 if none
    det_person: np.ndarray  # (det,) matched person, -1 if none
    nearest: np.ndarray  # (det,) closest person among the close ones, -1 if none


def _match_image(
    gt_px: np.ndarray,
    inside: np.ndarray,
    counted: np.ndarray,
    det_px: np.ndarray,
    threshold_px: float,
    min_common_joints: int,
) -> _ImageMatch:
    """One-to-one matching of the detections of one image to its counted ground-truth people."""
    common = inside[:, None, :] & np.isfinite(det_px).all(-1)[None, :, :]
    dist = np.where(common, np.linalg.norm(gt_px[:, None] - det_px[None], axis=-1), np.nan)
    n_common = common.sum(-1)
    mean = np.where(common, dist, 0.0).sum(-1) / np.maximum(n_common, 1)
    close = (n_common >= min_common_joints) & (mean < threshold_px)
    feasible = close & counted[:, None]
    person_det = np.full(len(gt_px), -1)
    det_person = np.full(len(det_px), -1)
    if feasible.any():
        rows, cols = linear_sum_assignment(np.where(feasible, mean, 1e12))
        ok = feasible[rows, cols]
        person_det[rows[ok]] = cols[ok]
        det_person[cols[ok]] = rows[ok]
    nearest = np.where(close.any(0), np.argmin(np.where(close, mean, np.inf), axis=0), -1) if len(gt_px) else det_person
    return _ImageMatch(dist, common, mean, person_det, det_person, nearest)


def _group_rows(table: pd.DataFrame, keys: list[str]) -> dict[tuple, np.ndarray]:
    """Positional row indices of ``table`` per distinct value of ``keys`` (tuples of Python scalars)."""
    if not len(table):
        return {}
    codes = [pd.factorize(table[k], sort=True) for k in keys]
    combined = np.zeros(len(table), dtype=np.int64)
    for c, uniques in codes:
        combined = combined * (len(uniques) + 1) + c
    order = np.argsort(combined, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(combined[order]) != 0])
    out = {}
    for block in np.split(order, starts[1:]):
        first = block[0]
        key = tuple(_py(uniques[c[first]]) for c, uniques in codes)
        out[key] = block
    return out


def _py(value):
    return value.item() if hasattr(value, "item") else value
