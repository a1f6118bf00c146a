"""Accuracy of the 2D-to-3D lifter against the ground truth: root-relative 3D pose and standing height.

Protocol (method ``"lifter"``), one lifted detection at a time:

* **Evaluated detections**: rows of the ``lifted_detections`` table with ``lifted`` True whose
  (frame, view, det_id) has ``person_id >= 0`` in the ``associations`` table (ground-truth identity: evaluation
  only), whose person has a ground-truth pose in that frame with both hips valid. False positives
  (``person_id`` -1), detections absent from the associations and detections the lifter did not lift are
  ignored.
* **Ground truth**: the person's world joints read under the canonical joint names
  (:func:`humancal.tables.poses.poses_to_dense` over ``CANONICAL_JOINTS``; other names are ignored), moved into the
  detection's view with the ground-truth camera (``x_cam = R_cam_from_world x_world + t_cam_from_world_m``) and
  made relative to the **hip midpoint** (mean of ``left_hip`` and ``right_hip``). Synthetic scenes give all 23
  canonical joints. Shelf's ground truth (``humancal.datasets.shelf``, SHELF15 names) shares 12 names with the
  canonical set: left/right shoulder, elbow, wrist, hip, knee and ankle; its ``bottom_head`` (neck),
  ``top_head`` and ``pelvis`` have no canonical equivalent and are not compared, and the root is the midpoint
  of its two hip joints, not its ``pelvis`` joint.
* **Lifted pose**: the crop-frame pose turned into the camera frame with the ground-truth intrinsics
  (:meth:`humancal.lifter.LiftedPoses.in_camera_frame`; lens distortion ignored), made relative to its own hip
  midpoint (already zero by construction). Joint j of the lifted pose is compared with the ground-truth joint
  of the same name: the lifted pose is in the detection's label order, so a detection whose left/right labels
  the detector swapped counts with the swap.
* **Compared joints**: those valid in the ground truth (and finite in the lifted pose): all 23 for synthetic
  scenes, the 12 above for Shelf.
* ``mpjpe_mm``: mean Euclidean error over all compared joints of all evaluated detections, millimetres.
  ``pa_mpjpe_mm``: the same after aligning each detection's lifted joints to its ground truth with the
  least-squares similarity (scale, rotation, translation; :func:`evaluation.metrics.pa_mpjpe_mm`).
* ``height_error_mm`` / ``height_bias_mm``: mean absolute / signed difference between the lifter's
  ``height_m`` and the person's true standing height (:func:`true_heights_m`: the ``people`` table's
  ``height_m`` where it has the person, otherwise derived from the ground-truth poses), over the evaluated
  detections whose person has a true height.
* ``num_detections``: how many detections were evaluated (unit ``count``).

Aggregates: the name without suffix and without a view pools every evaluated detection (not the mean over views,
unlike :mod:`evaluation.camera_metrics`); the rows with ``view`` v pool the evaluated detections of view v (only
views that have some); ``<metric>/upright`` pools those whose stored ``upright_score`` (the crop-frame score the
calibration reads) is at least :data:`UPRIGHT_THRESHOLD`. A figure with nothing to average (e.g. no true
heights known) is left out rather than written as NaN; with no evaluated detection at all the table is empty.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from evaluation.metrics import mpjpe_mm, pa_mpjpe_mm
from evaluation.protocols import MetricRow, metrics_table
from humancal.camera import cameras_from_table
from humancal.keypoints import CANONICAL_JOINTS
from humancal.lifter import ROOT_JOINTS, height_from_pose_m, lifted_from_table, root_relative
from humancal.tables.associations import Associations
from humancal.tables.poses import poses_to_dense

__all__ = [
    "METHOD",
    "SOLE_BELOW_ANKLE_M",
    "UPRIGHT_THRESHOLD",
    "LifterComparison",
    "compare_lifted_to_gt",
    "lifter_metrics",
    "lifter_metrics_table",
    "shelf_heights_m",
    "true_heights_m",
]

METHOD = "lifter"

UPRIGHT_THRESHOLD = 0.5
"""Detections whose stored ``upright_score`` is at least this form the ``/upright`` rows."""

SOLE_BELOW_ANKLE_M = 0.07
"""Height of the ankle joint above the soles added to the Shelf head-top-to-ankle span, metres."""

_HIPS = list(ROOT_JOINTS)


def shelf_heights_m(gt_poses3d: pd.DataFrame) -> pd.Series:
    """Standing height of every person of a SHELF15 ground truth (``top_head`` and ankles, world Z up).

    Per annotated frame: ``top_head`` z minus the lower of the two ankles' z; per person the median over
    frames (robust to the few frames where an actor bends or lifts a foot) plus :data:`SOLE_BELOW_ANKLE_M`.
    The rule the Shelf stand-in lifter uses (``scripts/calibration_sweep.py``).

    Args:
        gt_poses3d: ``poses3d`` table with ``top_head``, ``left_ankle`` and ``right_ankle`` rows, metres.

    Returns:
        Heights in metres indexed by ``person_id`` (persons without a usable frame are left out).
    """
    g = poses_to_dense(gt_poses3d, ("top_head", "left_ankle", "right_ankle"))
    z = g.joints_world_m[..., 2]  # (N, 3), NaN where invalid
    span = z[:, 0] - np.minimum(z[:, 1], z[:, 2])  # NaN where a joint is missing: that frame is skipped
    return _median_per_person(g.person_id, span + SOLE_BELOW_ANKLE_M)


def _median_per_person(person_id: np.ndarray, values: np.ndarray) -> pd.Series:
    s = pd.Series(values, index=pd.Index(person_id, name="person_id"), name="height_m").dropna()
    return s.groupby(level=0).median()


def true_heights_m(gt_poses3d: pd.DataFrame, gt_people: pd.DataFrame) -> pd.Series:
    """The true standing height of every person, metres, indexed by ``person_id``.

    The ``people`` table's ``height_m`` where it has a finite one for the person (synthetic scenes). Otherwise
    from the ground-truth poses: :func:`shelf_heights_m` when the poses carry ``top_head`` (Shelf), else the
    median over frames of :func:`humancal.lifter.height_from_pose_m` of the canonical joints (the lifter's own
    height rule applied to the truth). Persons with neither are left out.
    """
    known = gt_people.set_index("person_id")["height_m"].astype(np.float64)
    known = known[np.isfinite(known)]
    unknown = gt_poses3d[~gt_poses3d["person_id"].isin(known.index)]
    if len(unknown) and (unknown["joint"] == "top_head").any():
        derived = shelf_heights_m(unknown)
    elif len(unknown):
        g = poses_to_dense(unknown, CANONICAL_JOINTS)
        derived = _median_per_person(g.person_id, height_from_pose_m(g.joints_world_m))
    else:
        derived = pd.Series(dtype=np.float64)
    out = pd.concat([known, derived]).sort_index()
    out.index.name, out.name = "person_id", "height_m"
    return out


@dataclass(frozen=True)
class LifterComparison:
    """Lifted poses of the evaluated detections next to their ground truth, N detections.

    Attributes:
        view: (N,) view of each detection.
        lifted_m: (N, 23, 3) lifted joints, camera frame, relative to the hip midpoint, metres.
        gt_m: (N, 23, 3) ground-truth joints, same frame and root, metres (NaN where not valid).
        compared: (N, 23) joints compared (valid in the ground truth, finite in the lifted pose).
        height_m: (N,) the lifter's standing height, metres.
        true_height_m: (N,) the person's true standing height, metres (NaN where unknown).
        upright_score: (N,) the stored (crop-frame) upright score.
    """

    view: np.ndarray
    lifted_m: np.ndarray
    gt_m: np.ndarray
    compared: np.ndarray
    height_m: np.ndarray
    true_height_m: np.ndarray
    upright_score: np.ndarray

    def __len__(self) -> int:
        return len(self.view)


def compare_lifted_to_gt(
    lifted_detections: pd.DataFrame,
    associations: pd.DataFrame,
    gt_poses3d: pd.DataFrame,
    gt_cameras: pd.DataFrame,
    gt_people: pd.DataFrame,
) -> LifterComparison:
    """Select the evaluated detections and bring lifted and true poses into one frame (module docstring).

    Args:
        lifted_detections: canonical ``lifted_detections`` table.
        associations: canonical ``associations`` table (true ``person_id``; -1 rows are ignored).
        gt_poses3d: ground-truth ``poses3d`` (canonical names, or SHELF15 names for Shelf).
        gt_cameras: ground-truth ``cameras`` table (views 0..V-1).
        gt_people: ``people`` table (may be empty).

    Returns:
        The :class:`LifterComparison` (N = 0 when nothing qualifies).

    Raises:
        ValueError: an evaluated detection's view has no ground-truth camera.
    """
    dense, lifted = lifted_from_table(lifted_detections)
    person = Associations.from_table(associations).person_of_detections(dense)
    g = poses_to_dense(gt_poses3d, CANONICAL_JOINTS)
    gt_row = {(f, p): n for n, (f, p) in enumerate(zip(g.frame, g.person_id))}
    row = np.array([gt_row.get((f, p), -1) for f, p in zip(dense.frame, person)], dtype=np.int64)
    keep = lifted.valid & (person >= 0) & (row >= 0)
    keep[keep] = g.valid[row[keep]][:, _HIPS].all(axis=1)
    row, view = row[keep], dense.view[keep]

    cameras = cameras_from_table(gt_cameras)
    if len(view) and view.max() >= len(cameras):
        raise ValueError(f"lifter metrics: detections of view {int(view.max())} but only {len(cameras)} cameras")
    K = np.stack([c.K for c in cameras])[view] if len(view) else np.zeros((0, 3, 3))
    R = np.stack([c.R_cam_from_world for c in cameras])[view] if len(view) else np.zeros((0, 3, 3))
    lifted_cam = root_relative(lifted.subset(keep).in_camera_frame(K).joints_cam_m)
    gt_cam = np.einsum("nij,nkj->nki", R, root_relative(g.joints_world_m[row]))  # translation cancels
    compared = g.valid[row] & np.isfinite(lifted_cam).all(-1)

    heights = true_heights_m(gt_poses3d, gt_people)
    true_height = heights.reindex(person[keep]).to_numpy(np.float64)
    return LifterComparison(view, lifted_cam, gt_cam, compared, lifted.height_m[keep], true_height,
                            lifted.upright_score[keep])


def _rows(c: LifterComparison, sel: np.ndarray, suffix: str, view: int | None = None) -> list[MetricRow]:
    """Metric rows of the detections ``sel`` (names get ``suffix``, rows get ``view``), figures with nothing to
    average left out."""
    rows = [
        MetricRow(f"mpjpe_mm{suffix}", mpjpe_mm(c.lifted_m[sel], c.gt_m[sel], c.compared[sel]), "mm", view),
        MetricRow(f"pa_mpjpe_mm{suffix}", pa_mpjpe_mm(c.lifted_m[sel], c.gt_m[sel], c.compared[sel]), "mm", view),
    ]
    diff_mm = 1000.0 * (c.height_m[sel] - c.true_height_m[sel])
    diff_mm = diff_mm[np.isfinite(diff_mm)]
    if len(diff_mm):
        rows += [MetricRow(f"height_error_mm{suffix}", float(np.abs(diff_mm).mean()), "mm", view),
                 MetricRow(f"height_bias_mm{suffix}", float(diff_mm.mean()), "mm", view)]
    rows.append(MetricRow(f"num_detections{suffix}", float(sel.sum()), "count", view))
    return [r for r in rows if np.isfinite(r.value)]


def lifter_metrics(comparison: LifterComparison) -> list[MetricRow]:
    """All lifter metrics of a comparison: pooled, per view (``view`` set) and ``/upright`` rows (empty when
    N = 0)."""
    c = comparison
    if len(c) == 0:
        return []
    rows = _rows(c, np.ones(len(c), bool), "")
    for v in np.unique(c.view):
        rows += _rows(c, c.view == v, "", view=int(v))
    upright = c.upright_score >= UPRIGHT_THRESHOLD  # NaN scores compare False
    if upright.any():
        rows += _rows(c, upright, "/upright")
    return rows


def lifter_metrics_table(
    dataset: str,
    sequence: str,
    lifted_detections: pd.DataFrame,
    associations: pd.DataFrame,
    gt_poses3d: pd.DataFrame,
    gt_cameras: pd.DataFrame,
    gt_people: pd.DataFrame,
) -> pd.DataFrame:
    """The canonical ``metrics`` table of the lifter (method ``"lifter"``) on one sequence.

    Args:
        dataset, sequence: written into every row.
        lifted_detections: canonical ``lifted_detections`` table (crop-frame poses).
        associations: canonical ``associations`` table (ground-truth identities).
        gt_poses3d: ground-truth ``poses3d`` (canonical names; SHELF15 names for Shelf).
        gt_cameras: ground-truth ``cameras``.
        gt_people: ``people`` table (empty for Shelf: heights then come from the poses).

    Returns:
        Rows ``mpjpe_mm``, ``pa_mpjpe_mm``, ``height_error_mm``, ``height_bias_mm`` (mm) and ``num_detections``
        (count), each pooled, per view (``view`` column) and over upright detections (``/upright``), see the module
        docstring; an empty table when no detection qualifies.
    """
    comparison = compare_lifted_to_gt(lifted_detections, associations, gt_poses3d, gt_cameras, gt_people)
    return metrics_table(dataset, sequence, METHOD, lifter_metrics(comparison))
