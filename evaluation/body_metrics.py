"""Figures of the fitted bodies against the ground truth, beside the triangulated skeletons they start from.

Methods (metric-table names): the pipeline's own fit (``int_ext`` with the default settings: cameras refined
with the bodies; :data:`PIPELINE_METHOD`), and ``skeletons3d`` / ``skeletons3d_gt_cameras``, the association's
triangulated skeletons (the fits' baseline). The other regimes of the paper's Tables are fitted and scored by
``evaluation.method_comparison`` with the rows defined here.

Every fitted person is matched to a true person per frame through the detections it was fitted to (as the
skeletons: ``evaluation.association_metrics.skeletons_in_truth``) and moved into the ground-truth world by the
similarity that aligns the cameras. Figures: the dataset's protocol (Shelf: ``pcp_actor1``..``pcp_actor3``,
``pcp_avg``, ``mpjpe_mm``, the head joints derived from the fitted body's nose, ears and shoulders by the same rule
as every other Shelf row; synthetic: ``mpjpe_mm``, ``pa_mpjpe_mm``, ``pcp_avg``), ``accel_error_mm_s2`` (where the
ground truth has every frame: synthetic), ``pve_mm`` (synthetic: the people are anny bodies, so vertices compare
one to one), ``reprojection_error_px`` (fitted keypoints against the detections they were fitted to, in the
estimated world) and ``seconds``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import torch

from evaluation.association_metrics import associate_tables, protocol_of, skeletons_in_truth
from evaluation.camera_metrics import camera_metrics
from evaluation.protocols import MetricRow, evaluate_reprojection, metrics_table
from humancal.body import BodyModel
from humancal.calibration.rig_alignment import align_rig
from humancal.camera import CameraRig
from humancal.datasets.sequences import SequenceSpec
from humancal.fitting import FittedMotions
from humancal.keypoints import CANONICAL_JOINTS
from humancal.lifter import lifted_from_table
from humancal.tables.poses import poses_to_dense

__all__ = ["PIPELINE_METHOD", "body_metric_rows", "camera_and_body_rows", "keypoints_table", "pipeline_body_table", "skeleton_accel_rows"]

PVE_MAX_FRAMES = 60
"""Frames per person whose vertices the PVE compares (evenly spread; a full mesh per frame is costly)."""


def keypoints_table(motions: pd.DataFrame) -> pd.DataFrame:
    """The fitted keypoints of a ``motions`` table as a ``skeletons3d``-like table (frame, person_id, joint, x_m,
    y_m, z_m, valid), for the protocols."""
    n = len(motions)
    xyz = np.stack(motions["keypoints_world_m"].to_numpy()).reshape(n * len(CANONICAL_JOINTS), 3) if n else \
        np.zeros((0, 3))
    return pd.DataFrame({
        "sequence": np.repeat(motions["sequence"].to_numpy(), len(CANONICAL_JOINTS)),
        "frame": np.repeat(motions["frame"].to_numpy(np.int32), len(CANONICAL_JOINTS)),
        "person_id": np.repeat(motions["person_id"].to_numpy(np.int32), len(CANONICAL_JOINTS)),
        "joint": np.tile(np.asarray(CANONICAL_JOINTS, dtype=object), n),
        "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2],
        "valid": np.isfinite(xyz).all(1),
    })


def _accel_error_mm_s2(poses: pd.DataFrame, gt_poses3d: pd.DataFrame, fps: float) -> float:
    """Mean acceleration error over every run of >= 3 consecutive frames where both sides have the joint."""
    g = poses_to_dense(gt_poses3d, CANONICAL_JOINTS)
    p = poses_to_dense(poses, CANONICAL_JOINTS)
    index = {(f, i): n for n, (f, i) in enumerate(zip(p.frame, p.person_id))}
    errors = []
    for person in np.unique(g.person_id):
        rows = np.flatnonzero(g.person_id == person)
        rows = rows[np.argsort(g.frame[rows])]
        frames = g.frame[rows]
        pred = np.full((len(rows), len(CANONICAL_JOINTS), 3), np.nan)
        has = np.array([index.get((f, person), -1) for f in frames])
        pred[has >= 0] = p.joints_world_m[has[has >= 0]]
        gt = g.joints_world_m[rows]
        consecutive = (frames[2:] - frames[:-2]) == 2
        acc = lambda x: x[2:] - 2.0 * x[1:-1] + x[:-2]  # noqa: E731
        diff = np.linalg.norm(acc(pred) - acc(gt), axis=-1)[consecutive]
        errors.append(diff[np.isfinite(diff)])
    values = np.concatenate(errors) if errors else np.zeros(0)
    return float(1000.0 * values.mean() * fps**2) if values.size else float("nan")


def _pve_mm(motions: FittedMotions, gt_motions: FittedMotions, true_of: dict[int, int], to_truth, body: BodyModel) -> float:
    """Mean vertex error of each fitted person against the true person they are matched to (whole-sequence
    majority), over up to ``PVE_MAX_FRAMES`` frames each, in the ground-truth world."""
    errors = []
    for p, pid in enumerate(motions.person_ids.tolist()):
        if pid not in true_of or true_of[pid] not in gt_motions.person_ids.tolist():
            continue
        q = int(np.flatnonzero(gt_motions.person_ids == true_of[pid])[0])
        frames = np.intersect1d(motions.frames[motions.present[p]], gt_motions.frames[gt_motions.present[q]])
        if frames.size == 0:
            continue
        frames = frames[np.linspace(0, frames.size - 1, min(PVE_MAX_FRAMES, frames.size)).round().astype(int)]
        a = np.searchsorted(motions.frames, frames)
        b = np.searchsorted(gt_motions.frames, frames)
        as_t = lambda x: torch.as_tensor(x, dtype=body.dtype)  # noqa: E731
        with torch.no_grad():
            fit = body.reference_forward(as_t(motions.phenotypes[p:p + 1]), as_t(motions.bone_rotmats_local[p:p + 1, a]),
                                         as_t(motions.root_translation_m[p:p + 1, a]))["vertices"][0].double().numpy()
            gt = body.reference_forward(as_t(gt_motions.phenotypes[q:q + 1]), as_t(gt_motions.bone_rotmats_local[q:q + 1, b]),
                                        as_t(gt_motions.root_translation_m[q:q + 1, b]))["vertices"][0].double().numpy()
        errors.append(np.linalg.norm(to_truth(fit) - gt, axis=-1).mean(axis=-1))
    return float(1000.0 * np.concatenate(errors).mean()) if errors else float("nan")


def _whole_sequence_owner(associations: pd.DataFrame, gt_associations: pd.DataFrame) -> dict[int, int]:
    """Estimated person id -> the true id holding most of its detections over the whole sequence."""
    from humancal.tables.associations import Associations

    est = associations[associations["person_id"] >= 0]
    true = Associations.from_table(gt_associations).person_of(est["frame"], est["view"], est["det_id"])
    pairs = pd.DataFrame({"est": est["person_id"].to_numpy(), "true": true})
    pairs = pairs[pairs["true"] >= 0]
    if pairs.empty:
        return {}
    counts = pairs.groupby(["est", "true"]).size().rename("n").reset_index().sort_values("n", ascending=False)
    return {int(r.est): int(r.true) for r in counts.drop_duplicates("est").itertuples()}


def body_metric_rows(spec: SequenceSpec, *, motions: pd.DataFrame, fps: float, seconds: float,
                     associations: pd.DataFrame, detections: pd.DataFrame, cameras: CameraRig,
                     gt_associations: pd.DataFrame, gt_poses3d: pd.DataFrame, gt_cameras: CameraRig,
                     gt_motions: pd.DataFrame | None = None, body: BodyModel | None = None) -> list[MetricRow]:
    """The figures of one body fit (module docstring).

    Args:
        motions: the fit's ``motions`` table.
        fps: the sequence's frame rate.
        seconds: the fit's wall time.
        associations: the associations the fit was made from.
        detections: the ``detections`` (2D) the fit was made from (for the reprojection error).
        cameras: the cameras the fit was made with; ``gt_cameras`` the true ones.
        gt_motions: the true ``motions`` (synthetic scenes) for ``pve_mm``; None or empty: no PVE.
        body: the body model (needed with ``gt_motions``).
    """
    protocol = protocol_of(spec)
    fitted = keypoints_table(motions)
    in_truth = skeletons_in_truth(associations, fitted, gt_associations, cameras, gt_cameras)
    rows = protocol(in_truth, gt_poses3d)
    if spec.kind == "synthetic":
        rows.append(MetricRow("accel_error_mm_s2", _accel_error_mm_s2(in_truth, gt_poses3d, fps), "mm/s^2"))
        if gt_motions is not None and len(gt_motions) and body is not None and len(motions):
            similarity = align_rig(cameras, gt_cameras)
            pve = _pve_mm(FittedMotions.from_table(motions, fps), FittedMotions.from_table(gt_motions, fps),
                          _whole_sequence_owner(associations, gt_associations), similarity.apply, body)
            rows.append(MetricRow("pve_mm", pve, "mm"))
    reprojection = evaluate_reprojection(fitted, detections, associations, cameras)
    rows += [r for r in reprojection if r.metric in ("reprojection_error_px", "reprojection_error_median_px")]
    rows.append(MetricRow("seconds", float(seconds), "s"))
    return rows


def skeleton_accel_rows(spec: SequenceSpec, *, skeletons3d: pd.DataFrame, associations: pd.DataFrame, fps: float,
                        cameras: CameraRig, gt_associations: pd.DataFrame, gt_poses3d: pd.DataFrame,
                        gt_cameras: CameraRig) -> list[MetricRow]:
    """The baseline's figures under the same protocol as the fits (``skeletons3d`` rows)."""
    in_truth = skeletons_in_truth(associations, skeletons3d, gt_associations, cameras, gt_cameras)
    rows = protocol_of(spec)(in_truth, gt_poses3d)
    if spec.kind == "synthetic":
        rows.append(MetricRow("accel_error_mm_s2", _accel_error_mm_s2(in_truth, gt_poses3d, fps), "mm/s^2"))
    return rows


def camera_and_body_rows(spec: SequenceSpec, *, motions: pd.DataFrame, cameras: CameraRig, seconds: float,
                         associations: pd.DataFrame, detections: pd.DataFrame, gt_associations: pd.DataFrame,
                         gt_poses3d: pd.DataFrame, gt_cameras: CameraRig, gt_motions: pd.DataFrame | None,
                         body: BodyModel, fps: float, with_cameras: bool) -> list[MetricRow]:
    """The body rows of one fit (its reprojection error named ``fit_reprojection_error_px``) and, with
    ``with_cameras``, the camera rows of the cameras it ended with."""
    rows = body_metric_rows(spec, motions=motions, fps=fps, seconds=seconds, associations=associations,
                            detections=detections, cameras=cameras, gt_associations=gt_associations,
                            gt_poses3d=gt_poses3d, gt_cameras=gt_cameras, gt_motions=gt_motions, body=body)
    rows = [MetricRow("fit_" + r.metric, r.value, r.unit, view=r.view) if r.metric.startswith("reprojection")
            else r for r in rows]
    return camera_metrics(cameras, gt_cameras, detections, gt_associations) + rows if with_cameras else rows


PIPELINE_METHOD = {"int_ext": "int_ext", "ext": "ext_init_focal", "fixed": "init"}
"""The method name of the pipeline's own fit per camera regime (``BodyFitConfig.cameras``): with the default
(``int_ext``) the fit is the paper's fully self-calibrated row; with the cameras held it is the ``init`` row."""


def pipeline_body_table(spec: SequenceSpec, *, body: BodyModel, regime: str, fps: float, fitted_motions: pd.DataFrame,
                        refined_cameras: CameraRig, fit_seconds: float, associations: pd.DataFrame,
                        skeletons3d: pd.DataFrame, lifted_detections: pd.DataFrame, detections: pd.DataFrame,
                        cameras: CameraRig, gt_associations: pd.DataFrame, gt_poses3d: pd.DataFrame,
                        gt_cameras: CameraRig, gt_motions: pd.DataFrame | None,
                        failed_checks: str | None = None,
                        gt_cameras_association: tuple[pd.DataFrame, pd.DataFrame, float] | None = None
                        ) -> pd.DataFrame:
    """Rows of the pipeline's own fit (method :data:`PIPELINE_METHOD` of its regime: body rows, and the refined
    cameras' rows when they moved) and of the triangulated skeletons it started from (``skeletons3d``; and
    ``skeletons3d_gt_cameras``, the association redone with the true cameras, evaluation only).

    Args:
        regime: the fit's camera regime; refined_cameras: the cameras it ended with; fit_seconds: its wall time.
        associations, skeletons3d: the pipeline's association (init cameras); cameras: the init cameras.
        lifted_detections: the ``detections`` asset (2D + lifted), for the association with the true cameras.
        detections: the 2D detections.
        failed_checks: the checks the init cameras failed (as the camera rows).
        gt_cameras_association: :func:`evaluation.association_metrics.associate_tables` with the true cameras, when
            the caller has it already (computed here otherwise).
    """
    parts = []
    rows = camera_and_body_rows(
        spec, motions=fitted_motions, cameras=refined_cameras, seconds=fit_seconds, associations=associations,
        detections=detections, gt_associations=gt_associations, gt_poses3d=gt_poses3d, gt_cameras=gt_cameras,
        gt_motions=gt_motions, body=body, fps=fps, with_cameras=regime != "fixed")
    parts.append(metrics_table(spec.dataset, spec.sequence, PIPELINE_METHOD[regime], rows, failed_checks))
    gt_people, gt_skeletons, _ = (gt_cameras_association
                                  or associate_tables(*lifted_from_table(lifted_detections), gt_cameras, spec.sequence))
    for method, (people, skeletons, used, failed) in {
        "skeletons3d": (associations, skeletons3d, cameras, failed_checks),
        "skeletons3d_gt_cameras": (gt_people, gt_skeletons, gt_cameras, None),
    }.items():
        rows = skeleton_accel_rows(spec, skeletons3d=skeletons, associations=people, fps=fps, cameras=used,
                                   gt_associations=gt_associations, gt_poses3d=gt_poses3d, gt_cameras=gt_cameras)
        parts.append(metrics_table(spec.dataset, spec.sequence, method, rows, failed))
    return pd.concat(parts, ignore_index=True)
