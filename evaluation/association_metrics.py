"""Who-is-who figures of an association against the ground-truth identities, and the 3D accuracy of its
skeletons (the dataset's protocol).

Identity figures (detections meet the ground truth by (frame, view, det_id); a detection the ground truth calls
``-1`` or does not list is a false positive):

* ``pairwise_precision`` / ``pairwise_recall`` / ``pairwise_f1``: over the pairs of detections of one frame in
  different views, "same person" as estimated against as true (rejected detections are nobody's).
* ``id_switches``: per true person and frame, the estimated id holding most of its detections; a switch is a
  change of that id between consecutive frames the person was found in (summed over people).
* ``idf1``: the identity F1 of multi-target tracking (estimated ids matched one-to-one to true ids over the whole
  sequence so as to agree on the most detections; ``2 IDTP / (2 IDTP + IDFP + IDFN)`` over detections).
* ``fp_rejection_rate``: percent of the true false positives labelled -1 (NaN where there are none).
* ``num_people_error``: estimated minus true number of people.

Ground truth that names only some of the people (Shelf: actors 1-3 are annotated, in the frames with annotations;
a fourth person and the unannotated frames are ``-1`` there, which is not "false positive") is *partial*: the
pairwise figures and the switches then count only detections of annotated people (pairs with an unannotated
detection are unknown, not wrong), and ``fp_rejection_rate`` and ``num_people_error`` are NaN (the truth does not
say which detections are false positives, nor how many people there are). Synthetic ground truth is complete.

3D figures: each estimated skeleton takes, per frame, the true id of most of its detections (a true person
claimed twice in a frame keeps the skeleton with more views); the skeletons are brought into the ground-truth
world by the similarity that aligns the estimated camera centres on the true ones (as the camera metrics do),
then scored by the dataset's protocol (``mpjpe_mm``, ``pcp_avg``; Shelf: actors 1-3).
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment

from evaluation.protocols import MetricRow, evaluate_canonical_poses, evaluate_shelf_poses, metrics_table
from humancal.association import AffinityConfig, TrackingConfig, associate, to_associations_table, to_skeletons_table
from humancal.calibration.rig_alignment import align_rig
from humancal.camera import CameraRig
from humancal.datasets.sequences import SequenceSpec
from humancal.lifter import LiftedPoses
from humancal.tables.associations import Associations
from humancal.tables.detections import DenseDetections

__all__ = ["identity_metrics", "identity_confusion", "skeleton_metrics", "skeletons_in_truth", "protocol_of",
           "association_metric_table"]

_KEYS = ["frame", "view", "det_id"]


def _labelled(estimated: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """frame, view, est, true of every estimated detection (true -1 where the ground truth says none)."""
    true = Associations.from_table(truth).person_of(*(estimated[k].to_numpy() for k in _KEYS))
    return pd.DataFrame({"frame": estimated["frame"].to_numpy(np.int64), "view": estimated["view"].to_numpy(np.int64),
                         "est": estimated["person_id"].to_numpy(np.int64), "true": true.astype(np.int64)})


def _cross_view_pairs(df: pd.DataFrame, keys: list[str]) -> int:
    """Pairs of rows in different views within each group of ``keys``."""
    if df.empty:
        return 0
    per_view = df.groupby([*keys, "view"]).size()
    n = per_view.groupby(level=list(range(len(keys)))).sum()
    squares = (per_view ** 2).groupby(level=list(range(len(keys)))).sum()
    return int(((n ** 2 - squares) // 2).sum())


def _majority(df: pd.DataFrame, by: list[str], label: str) -> pd.DataFrame:
    """For each group of ``by``, the value of ``label`` most of its rows hold, with that count (``votes``)."""
    counts = df.groupby([*by, label]).size().rename("votes").reset_index()
    return counts.sort_values([*by, "votes", label], ascending=[True] * len(by) + [False, True]).drop_duplicates(by)


def identity_metrics(estimated: pd.DataFrame, truth: pd.DataFrame, *, complete: bool = True) -> list[MetricRow]:
    """Pairwise precision/recall/F1, id switches, false-positive rejection and people count error.

    Args:
        estimated: ``associations`` table of the method.
        truth: ground-truth ``associations`` table.
        complete: whether the truth names every person (synthetic) or only some (Shelf: see the module docstring).
    """
    d = _labelled(estimated, truth)
    if not complete:  # unannotated detections are unknown, not false positives
        d = d[d["true"] >= 0]
    est, true = d[d["est"] >= 0], d[d["true"] >= 0]
    predicted = _cross_view_pairs(est, ["frame", "est"])
    actual = _cross_view_pairs(true, ["frame", "true"])
    hits = _cross_view_pairs(d[(d["est"] >= 0) & (d["true"] >= 0)], ["frame", "est", "true"])
    precision = hits / predicted if predicted else float("nan")
    recall = hits / actual if actual else float("nan")
    f1 = 2 * hits / (predicted + actual) if predicted + actual else float("nan")
    found = _majority(d[(d["est"] >= 0) & (d["true"] >= 0)], ["true", "frame"], "est").sort_values(["true", "frame"])
    same_person = found["true"].to_numpy()[1:] == found["true"].to_numpy()[:-1]
    switches = int((same_person & (found["est"].to_numpy()[1:] != found["est"].to_numpy()[:-1])).sum())
    false_positive = d["true"] < 0
    rejection = 100.0 * float((d.loc[false_positive, "est"] < 0).mean()) if false_positive.any() else float("nan")
    num_true = int(truth.loc[truth["person_id"] >= 0, "person_id"].nunique())
    people_error = float(est["est"].nunique() - num_true) if complete else float("nan")
    idf1 = _idf1(d)
    return [
        MetricRow("pairwise_precision", precision, "ratio"),
        MetricRow("pairwise_recall", recall, "ratio"),
        MetricRow("pairwise_f1", f1, "ratio"),
        MetricRow("id_switches", float(switches), "count"),
        MetricRow("idf1", idf1, "ratio"),
        MetricRow("fp_rejection_rate", rejection, "%"),
        MetricRow("num_people_error", people_error, "count"),
    ]


def identity_confusion(estimated: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Detections per (true person, estimated id): what merged (an id holding several people) or split (a person
    under several ids). Columns ``true``, ``est`` (-1: a false positive, a rejected detection) and ``detections``,
    largest first.

    Args:
        estimated: ``associations`` table of the method.
        truth: ground-truth ``associations`` table.
    """
    counts = _labelled(estimated, truth).groupby(["true", "est"]).size().rename("detections").reset_index()
    return counts.sort_values("detections", ascending=False, ignore_index=True)


def _idf1(d: pd.DataFrame) -> float:
    """Identity F1 of labelled detections ``d`` (columns ``est``, ``true``; -1: none)."""
    both = d[(d["est"] >= 0) & (d["true"] >= 0)]
    n_est, n_true = int((d["est"] >= 0).sum()), int((d["true"] >= 0).sum())
    if n_est + n_true == 0:
        return float("nan")
    if both.empty:
        return 0.0
    counts = both.groupby(["est", "true"]).size().unstack(fill_value=0)
    rows, cols = linear_sum_assignment(-counts.to_numpy())
    idtp = int(counts.to_numpy()[rows, cols].sum())
    return 2.0 * idtp / (n_est + n_true)  # 2 IDTP / (2 IDTP + IDFP + IDFN), IDFP = n_est - IDTP, IDFN = n_true - IDTP


_SEQUENCE_ALIGNED = {"pcp_avg": "pcp_avg_sequence_aligned", "mpjpe_mm": "mpjpe_sequence_aligned_mm"}


def skeletons_in_truth(estimated: pd.DataFrame, skeletons: pd.DataFrame, truth: pd.DataFrame,
                       cameras: CameraRig, gt_cameras: CameraRig) -> pd.DataFrame:
    """Estimated 3D keypoints as a ground-truth ``poses3d`` table: each skeleton takes, per frame, the true id of
    most of its detections (a true person claimed twice in a frame keeps the skeleton with more views), and moves
    into the ground-truth world by the similarity that aligns the estimated camera centres on the true ones.

    Args:
        estimated: ``associations`` table of the method.
        skeletons: per (frame, person_id, joint) estimated keypoints (``skeletons3d`` columns; any table with
            ``sequence, frame, person_id, joint, x_m, y_m, z_m, valid``).
        truth: ground-truth ``associations``.
        cameras, gt_cameras: the cameras the skeletons were made with, and the true ones.
    """
    d = _labelled(estimated, truth)
    owner = _majority(d[(d["est"] >= 0) & (d["true"] >= 0)], ["frame", "est"], "true")
    owner = owner.sort_values(["frame", "true", "votes"], ascending=[True, True, False]).drop_duplicates(["frame", "true"])
    mapped = skeletons.merge(owner.rename(columns={"est": "person_id", "true": "true_id"})[["frame", "person_id", "true_id"]],
                             on=["frame", "person_id"], how="inner")
    xyz = align_rig(cameras, gt_cameras).apply(mapped[["x_m", "y_m", "z_m"]].to_numpy())
    poses = pd.DataFrame({"sequence": mapped["sequence"], "frame": mapped["frame"].astype(np.int32),
                          "person_id": mapped["true_id"].astype(np.int32), "joint": mapped["joint"],
                          "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2],
                          "valid": mapped["valid"].to_numpy(bool) & np.isfinite(xyz).all(1)})
    poses.loc[~poses["valid"], ["x_m", "y_m", "z_m"]] = 0.0
    return poses


PROTOCOLS = {"shelf": evaluate_shelf_poses, "synthetic": evaluate_canonical_poses}
"""The 3D protocol of each dataset kind."""


def protocol_of(spec: SequenceSpec):
    """The 3D evaluation protocol of a sequence's dataset kind (ValueError where there is none)."""
    if spec.kind not in PROTOCOLS:
        raise ValueError(f"sequence {spec.key}: no evaluation protocol for dataset kind {spec.kind!r}")
    return PROTOCOLS[spec.kind]


def skeleton_metrics(spec: SequenceSpec, estimated: pd.DataFrame, skeletons: pd.DataFrame, truth: pd.DataFrame,
                     gt_poses3d: pd.DataFrame, cameras: CameraRig, gt_cameras: CameraRig) -> list[MetricRow]:
    """``mpjpe_mm`` and ``pcp_avg`` of the skeletons (ids mapped to the true ones per frame, aligned into the
    ground-truth world by the cameras' similarity: :func:`skeletons_in_truth`), by the dataset's protocol; and
    ``pcp_avg_sequence_aligned``, ``mpjpe_sequence_aligned_mm``: the same after one more similarity for the whole
    sequence, fitted on the evaluated joints (evaluation only; it shows how much of the error is the placement of
    the world)."""
    protocol = protocol_of(spec)
    poses = skeletons_in_truth(estimated, skeletons, truth, cameras, gt_cameras)
    rows = [r for r in protocol(poses, gt_poses3d) if r.metric in ("mpjpe_mm", "pcp_avg")]
    # The same skeletons in the frame that fits them best (one similarity for the sequence): what the
    # skeletons are worth apart from where the cameras put the world.
    rows += [MetricRow(_SEQUENCE_ALIGNED[r.metric], r.value, r.unit)
             for r in protocol(poses, gt_poses3d, sequence_aligned=True) if r.metric in _SEQUENCE_ALIGNED]
    return rows


def associate_tables(dense: DenseDetections, lifted: LiftedPoses, cameras: CameraRig, sequence: str,
                     affinity: AffinityConfig | None = None) -> tuple[pd.DataFrame, pd.DataFrame, float]:
    """The association of the lifted detections (``humancal.lifter.lifted_from_table`` of the ``detections``
    asset) with ``cameras``: its ``associations`` and ``skeletons3d`` tables and its run time, seconds. With the true
    cameras it is evaluation only."""
    start = time.perf_counter()
    result = associate(dense, lifted, CameraRig.of(cameras), TrackingConfig(affinity=affinity or AffinityConfig()))
    return (to_associations_table(result, sequence), to_skeletons_table(result, sequence),
            time.perf_counter() - start)


def association_metric_table(
    spec: SequenceSpec,
    *,
    associations: pd.DataFrame,
    skeletons3d: pd.DataFrame,
    seconds: float,
    dense: DenseDetections,
    lifted: LiftedPoses,
    cameras: CameraRig,
    gt_associations: pd.DataFrame,
    gt_poses3d: pd.DataFrame,
    gt_cameras: CameraRig,
    failed_checks: str | None = None,
    gt_cameras_association: tuple[pd.DataFrame, pd.DataFrame, float] | None = None,
) -> pd.DataFrame:
    """Rows of method ``association`` (the pipeline's tables), ``epipolar_only`` (the geometric affinity alone,
    associated here from the same detections and cameras; it never feeds the pipeline), and both again with the
    true cameras (``association_gt_cameras``, ``epipolar_only_gt_cameras``).

    Args:
        seconds: the pipeline association's run time, seconds (NaN where unknown).
        dense, lifted: the ``detections`` asset's detections and lifted poses
            (``humancal.lifter.lifted_from_table``), which the other methods associate.
        failed_checks: the checks the estimated cameras failed (as the camera rows).
        gt_cameras_association: :func:`associate_tables` with the true cameras and the default affinity, when the
            caller has it already (it is computed here otherwise).
    """
    parts = []

    def run(rig_cameras: CameraRig, affinity: AffinityConfig):
        return associate_tables(dense, lifted, rig_cameras, spec.sequence, affinity)

    # method -> (associations, skeletons, seconds, cameras used, failed checks of those cameras)
    methods = {
        "association": (associations, skeletons3d, seconds, cameras, failed_checks),
        "epipolar_only": (*run(cameras, AffinityConfig.epipolar_only()), cameras, failed_checks),
        # with the true cameras: what the association gives when the calibration is perfect (evaluation only)
        "association_gt_cameras": (*(gt_cameras_association or run(gt_cameras, AffinityConfig())), gt_cameras, None),
        "epipolar_only_gt_cameras": (*run(gt_cameras, AffinityConfig.epipolar_only()), gt_cameras, None),
    }
    for method, (people, skeletons, s, used, failed) in methods.items():
        rows = identity_metrics(people, gt_associations, complete=spec.kind == "synthetic")
        rows += skeleton_metrics(spec, people, skeletons, gt_associations, gt_poses3d, used, gt_cameras)
        rows.append(MetricRow("seconds", float(s), "s"))
        parts.append(metrics_table(spec.dataset, spec.sequence, method, rows, failed))
    return pd.concat(parts, ignore_index=True)
