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

from humancal.camera import Camera, CameraRig, project_points
from humancal.tables.schemas import validate_table

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
    cameras: CameraRig,
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
        humancal.tables.schemas.TableError: a table does not match its schema.
    """
    detections = validate_table(detections, "detections", source="match_ground_truth detections")
    gt_poses = validate_table(gt_poses, "poses3d", source="match_ground_truth gt_poses")
    _check_parameters(threshold_fraction, min_visible_fraction, min_common_joints)
    joints = _evaluated_joints(detections, gt_poses, joints)
    _check_views(detections, cameras)
    joint_index = {name: i for i, name in enumerate(joints)}
    dets = _index_detections(detections, joint_index)
    gt = _index_ground_truth(gt_poses, joint_index)
    min_visible = max(1, int(np.ceil(min_visible_fraction * len(joints))))

    rows = _MatchRows([], [], [])
    for (seq, frame), gt_rows in sorted(gt.rows_by_frame.items()):
        person_ids, people_m = _frame_people(gt, gt_rows, len(joints))
        for view, cam in enumerate(cameras):
            people = _project_people(cam, person_ids, people_m, min_visible)
            det_ids, det_px = _image_detections(dets, (seq, frame, view), len(joints))
            threshold_px = threshold_fraction * float(np.hypot(cam.width_px, cam.height_px))
            match = _match_image(people.px, people.inside, people.counted, det_px, threshold_px, min_common_joints)
            rows.extend(_image_rows((seq, frame, view), people, det_ids, match, joints))
    rows.extend(_rows_without_ground_truth(dets, gt.rows_by_frame))
    return rows.tables()


def _check_parameters(threshold_fraction: float, min_visible_fraction: float, min_common_joints: int) -> None:
    """Raise ``ValueError`` for a matching parameter out of its range."""
    if not 0.0 < threshold_fraction:
        raise ValueError(f"threshold_fraction must be > 0, got {threshold_fraction}")
    if not 0.0 <= min_visible_fraction <= 1.0:
        raise ValueError(f"min_visible_fraction must lie in [0, 1], got {min_visible_fraction}")
    if min_common_joints < 1:
        raise ValueError(f"min_common_joints must be >= 1, got {min_common_joints}")


def _evaluated_joints(detections: pd.DataFrame, gt_poses: pd.DataFrame, joints: Sequence[str] | None) -> list[str]:
    """The joint names to evaluate: ``joints``, or the names both tables use in ground-truth order; never empty."""
    if joints is None:
        det_names = set(detections["joint"].unique())
        joints = [j for j in dict.fromkeys(gt_poses["joint"]) if j in det_names]
    joints = list(joints)
    if not joints:
        raise ValueError(
            "match_ground_truth: the detections and the ground truth share no joint names "
            f"(ground truth has {sorted(gt_poses['joint'].unique())})"
        )
    return joints


def _check_views(detections: pd.DataFrame, cameras: CameraRig) -> None:
    """Raise ``ValueError`` when a detection names a view that has no camera."""
    views = sorted(detections["view"].unique().tolist())
    missing = [v for v in views if v >= len(cameras)]
    if missing:
        raise ValueError(f"match_ground_truth: detections name view(s) {missing} but only {len(cameras)} cameras given")


# Plain numpy arrays grouped by image or frame: pandas group objects are too slow for thousands of images.


@dataclass(frozen=True)
class _DetectionIndex:
    """The detections as flat arrays with their positions per image, keyed ``(sequence, frame, view)``.

    Attributes:
        ids_by_image: positions into ``all_det_id`` of every detection of each image, scored or not.
        all_det_id: (D,) ``det_id`` of each distinct (sequence, frame, view, det_id).
        rows_by_image: positions into the arrays below of each image's scored rows of evaluated joints.
        det_id: (N,) ``det_id`` of each scored row.
        joint: (N,) evaluated-joint index of each scored row.
        xy_px: (N, 2) detected position of each scored row, pixels.
    """

    ids_by_image: dict[tuple, np.ndarray]
    all_det_id: np.ndarray
    rows_by_image: dict[tuple, np.ndarray]
    det_id: np.ndarray
    joint: np.ndarray
    xy_px: np.ndarray


def _index_detections(detections: pd.DataFrame, joint_index: dict[str, int]) -> _DetectionIndex:
    """Index the detections by image; only rows with a positive score on an evaluated joint carry a position."""
    all_dets = detections[["sequence", "frame", "view", "det_id"]].drop_duplicates()
    det = detections[detections["joint"].isin(joint_index) & (detections["score"] > 0)]
    return _DetectionIndex(
        ids_by_image=_group_rows(all_dets, ["sequence", "frame", "view"]),
        all_det_id=all_dets["det_id"].to_numpy(),
        rows_by_image=_group_rows(det, ["sequence", "frame", "view"]),
        det_id=det["det_id"].to_numpy(),
        joint=det["joint"].map(joint_index).to_numpy(),
        xy_px=det[["x_px", "y_px"]].to_numpy(),
    )


@dataclass(frozen=True)
class _GroundTruthIndex:
    """The valid ground-truth rows of evaluated joints as flat arrays with their positions per ``(sequence, frame)``.

    Attributes:
        rows_by_frame: positions into the arrays below of each frame's rows.
        person_id: (N,) person of each row.
        joint: (N,) evaluated-joint index of each row.
        xyz_m: (N, 3) world position of each row, metres.
    """

    rows_by_frame: dict[tuple, np.ndarray]
    person_id: np.ndarray
    joint: np.ndarray
    xyz_m: np.ndarray


def _index_ground_truth(gt_poses: pd.DataFrame, joint_index: dict[str, int]) -> _GroundTruthIndex:
    """Index the valid ground-truth rows of evaluated joints by frame."""
    gt = gt_poses[gt_poses["joint"].isin(joint_index) & gt_poses["valid"]]
    return _GroundTruthIndex(
        rows_by_frame=_group_rows(gt, ["sequence", "frame"]),
        person_id=gt["person_id"].to_numpy(),
        joint=gt["joint"].map(joint_index).to_numpy(),
        xyz_m=gt[["x_m", "y_m", "z_m"]].to_numpy(),
    )


def _frame_people(gt: _GroundTruthIndex, rows: np.ndarray, num_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """The sorted person ids (P,) of one frame and their (P, J, 3) world joints in metres, NaN where absent."""
    person_ids = np.unique(gt.person_id[rows])
    people_m = np.full((len(person_ids), num_joints, 3), np.nan)
    people_m[np.searchsorted(person_ids, gt.person_id[rows]), gt.joint[rows]] = gt.xyz_m[rows]
    return person_ids, people_m


@dataclass(frozen=True)
class _ProjectedPeople:
    """The ground-truth people of one frame projected into one view.

    Attributes:
        person_ids: (P,) ground-truth person ids.
        px: (P, J, 2) projected joints, pixels.
        inside: (P, J) the projected joint is visible (finite, inside the image).
        counted: (P,) the person-view has enough visible joints to count.
    """

    person_ids: np.ndarray
    px: np.ndarray
    inside: np.ndarray
    counted: np.ndarray


def _project_people(cam: Camera, person_ids: np.ndarray, people_m: np.ndarray, min_visible: int) -> _ProjectedPeople:
    """Project a frame's people (P, J, 3) into ``cam`` and mark the visible joints and the counted person-views."""
    px, _ = project_points(cam, people_m)
    inside = (
        np.isfinite(px).all(-1)
        & (px[..., 0] >= 0)
        & (px[..., 0] < cam.width_px)
        & (px[..., 1] >= 0)
        & (px[..., 1] < cam.height_px)
    )
    return _ProjectedPeople(person_ids, px, inside, inside.sum(-1) >= min_visible)


def _image_detections(dets: _DetectionIndex, image: tuple, num_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """The sorted detection ids (D,) of one image and their (D, J, 2) joints in pixels, NaN where not detected."""
    ids = np.unique(dets.all_det_id[dets.ids_by_image.get(image, [])])
    det_px = np.full((len(ids), num_joints, 2), np.nan)
    rows = dets.rows_by_image.get(image, [])
    det_px[np.searchsorted(ids, dets.det_id[rows]), dets.joint[rows]] = dets.xy_px[rows]
    return ids, det_px


@dataclass(frozen=True)
class _MatchRows:
    """Row tuples of the three output tables, gathered image by image."""

    person_views: list[tuple]
    detections: list[tuple]
    joint_errors: list[tuple]

    def extend(self, other: _MatchRows) -> None:
        """Append ``other``'s rows after these."""
        self.person_views.extend(other.person_views)
        self.detections.extend(other.detections)
        self.joint_errors.extend(other.joint_errors)

    def tables(self) -> GroundTruthMatch:
        """The rows as the tables of :class:`GroundTruthMatch`."""
        person_views = pd.DataFrame(
            self.person_views,
            columns=["sequence", "frame", "view", "person_id", "counted", "visible_joints", "det_id", "mean_error_px"],
        )
        det_table = pd.DataFrame(
            self.detections,
            columns=["sequence", "frame", "view", "det_id", "matched_person", "nearest_person", "fragment"],
        )
        errors = pd.DataFrame(self.joint_errors, columns=["sequence", "frame", "view", "det_id", "joint", "error_px"])
        return GroundTruthMatch(person_views, det_table, errors)


def _image_rows(
    image: tuple, people: _ProjectedPeople, det_ids: np.ndarray, m: _ImageMatch, joints: list[str]
) -> _MatchRows:
    """The output rows of one ``(sequence, frame, view)`` image from its matching ``m``."""
    pids = people.person_ids
    rows = _MatchRows([], [], [])
    for p, d in enumerate(m.person_det):
        if d >= 0:
            rows.joint_errors.extend(
                (*image, int(det_ids[d]), joints[j], float(m.dist[p, d, j])) for j in np.flatnonzero(m.common[p, d])
            )
        rows.person_views.append(
            (
                *image,
                int(pids[p]),
                bool(people.counted[p]),
                int(people.inside[p].sum()),
                int(det_ids[d]) if d >= 0 else -1,
                float(m.mean[p, d]) if d >= 0 else np.nan,
            )
        )
    for d, det_id_d in enumerate(det_ids):
        matched = int(pids[m.det_person[d]]) if m.det_person[d] >= 0 else -1
        near = int(pids[m.nearest[d]]) if m.nearest[d] >= 0 else -1
        rows.detections.append((*image, int(det_id_d), matched, near, bool(near >= 0 and matched < 0)))
    return rows


def _rows_without_ground_truth(dets: _DetectionIndex, gt_frames: dict[tuple, np.ndarray]) -> _MatchRows:
    """Detection rows of the frames without any ground truth: neither matched nor fragments."""
    rows = _MatchRows([], [], [])
    for (seq, frame, view), ids in dets.ids_by_image.items():
        if (seq, frame) not in gt_frames:
            rows.detections.extend((seq, frame, view, int(d), -1, -1, False) for d in np.unique(dets.all_det_id[ids]))
    return rows


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
