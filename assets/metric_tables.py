"""Per sequence: every method's figures against the ground truth, in one metrics table."""

import tempfile
from dataclasses import dataclass
from pathlib import Path

import dagster as dg
import pandas as pd

from assets.common import png_metadata, sequence_asset, table_output
from assets.run_records import UNCHECKED, failed_checks, stage_seconds
from assets.settings import BodyFitSettings
from evaluation.association_metrics import association_metric_table
from evaluation.body_metrics import PIPELINE_METHOD, pipeline_body_table
from evaluation.camera_metrics import camera_metrics_table
from evaluation.lifter_metrics import lifter_metrics_table
from evaluation.rig_plot import plot_rig_comparison
from evaluation.sequence_metrics import sequence_metric_table
from humancal.camera import CameraRig, cameras_from_table
from humancal.datasets.inputs import body_fit_regime, sequence_fps
from humancal.lifter import lifted_from_table
from humancal.tables.schemas import empty_table
from resources.body_model import BodyModelResource
from resources.datasets import DatasetsResource
from resources.torch import TorchResource


@sequence_asset("metrics", code_version="18")
def metric_tables(
    context: dg.AssetExecutionContext,
    config: BodyFitSettings,
    datasets: DatasetsResource,
    body_model: BodyModelResource,
    torch_runtime: TorchResource,
    gt_camera_triangulation: pd.DataFrame,
    raw_detections: pd.DataFrame,
    detections: pd.DataFrame,
    extrinsics: pd.DataFrame,
    gt_cameras: pd.DataFrame,
    gt_poses3d: pd.DataFrame,
    gt_associations: pd.DataFrame,
    gt_people: pd.DataFrame,
    associations: pd.DataFrame,
    skeletons3d: pd.DataFrame,
    fitted_motions: pd.DataFrame,
    refined_cameras: pd.DataFrame,
    gt_motions: pd.DataFrame,
    gt_camera_associations: pd.DataFrame,
    gt_camera_skeletons3d: pd.DataFrame,
    run_records: pd.DataFrame,
) -> dg.Output:
    """MPJPE, PCP and reprojection error of each method; the lifter's 3D and height errors; the camera
    initialisation's focal, position, angle and reprojection errors; detection grouping on real datasets; who is
    who; the pipeline's fitted bodies and refined cameras (method ``int_ext`` with the default settings) against the
    triangulated skeletons (``evaluation.body_metrics``; ``config`` must be the body fit's: it names the regime).
    The other regimes of the paper's Tables are fitted by ``method_tables`` (on request).
    The camera rows name the checks of ``extrinsics`` that its cameras failed (column ``failed_checks``); those and
    the association's and the fit's seconds come from ``run_records``."""
    spec = datasets.spec(context.partition_key)
    gt = cameras_from_table(gt_cameras)
    estimated = cameras_from_table(extrinsics)
    # A user's capture may come without known cameras, identities or 3D poses: only the rows its ground truth
    # supports (camera errors need known cameras; everything else needs identities and poses too).
    identified = bool(gt) and len(gt_associations) > 0 and len(gt_poses3d) > 0
    parts = []
    if identified:
        parts += [
            sequence_metric_table(spec, gt_camera_triangulation=gt_camera_triangulation, detections=raw_detections,
                                  associations=gt_associations, cameras=gt, gt_poses3d=gt_poses3d),
            lifter_metrics_table(spec.dataset, spec.sequence, detections, gt_associations, gt_poses3d, gt_cameras,
                                 gt_people),
        ]
    if gt:
        failed = camera_checks_of(run_records, context.log)
        parts.append(camera_metrics_table(spec.dataset, spec.sequence, estimated, gt,
                                          raw_detections if identified else None, gt_associations if identified else None,
                                          failed_checks=failed))
        if not identified and len(refined_cameras):  # a capture with reference cameras: the refined rig's rows too
            parts.append(camera_metrics_table(spec.dataset, spec.sequence, cameras_from_table(refined_cameras), gt,
                                              method=PIPELINE_METHOD[body_fit_regime(spec, config.cameras)],
                                              failed_checks=failed))
        if identified:  # who is who and the bodies, against the true identities (the method never reads them)
            inputs = MethodInputs(raw_detections, detections, associations, skeletons3d, estimated, gt_associations,
                                  gt_poses3d, gt, (gt_camera_associations, gt_camera_skeletons3d,
                                                   stage_seconds(run_records, "gt_camera_associations")))
            parts.append(_association_rows(spec, inputs, run_records, failed))
            with torch_runtime.applied():
                parts.append(_body_rows(spec, inputs, config, body_model, fitted_motions, refined_cameras, gt_motions,
                                        run_records, failed))
    else:
        context.log.info(f"{spec.key}: no known cameras: no metric rows (the calibrated cameras are in extrinsics)")
    table = pd.concat(parts, ignore_index=True) if parts else empty_table("metrics")
    headline = table[table["view"].isna() & ~table["metric"].str.contains("/")].drop(columns="view")
    context.log.info(f"{spec.key}: {len(table)} metric rows ({len(headline)} headline)")
    pictures = _rig_pictures(spec.key, estimated, refined_cameras, gt, raw_detections, gt_associations,
                             config.cameras) if gt else {}
    return table_output(
        table, "metrics", rows=len(table), **pictures,
        summary=dg.MetadataValue.md(headline.to_markdown(index=False, floatfmt=".2f")),
    )


@dataclass(frozen=True)
class MethodInputs:
    """What the association's and the bodies' rows are scored from: the method's tables and the ground truth.

    Attributes:
        raw_detections, detections: the detections, and the lifted ones (tables ``detections``, ``lifted_detections``).
        associations, skeletons3d: the association's person ids and 3D joints.
        cameras: the estimated rig (``extrinsics``).
        gt_associations, gt_poses3d, gt_cameras: the ground truth.
        gt_cameras_association: the association with the true cameras (``gt_camera_associations``,
            ``gt_camera_skeletons3d``, its seconds).
    """

    raw_detections: pd.DataFrame
    detections: pd.DataFrame
    associations: pd.DataFrame
    skeletons3d: pd.DataFrame
    cameras: CameraRig
    gt_associations: pd.DataFrame
    gt_poses3d: pd.DataFrame
    gt_cameras: CameraRig
    gt_cameras_association: tuple[pd.DataFrame, pd.DataFrame, float]


def _association_rows(spec, inputs: MethodInputs, run_records: pd.DataFrame, failed: str) -> pd.DataFrame:
    """Who is who: the association with the estimated cameras and with the true ones (``association*`` rows)."""
    dense, lifted = lifted_from_table(inputs.detections)
    return association_metric_table(
        spec, associations=inputs.associations, skeletons3d=inputs.skeletons3d,
        seconds=stage_seconds(run_records, "associations"), dense=dense, lifted=lifted, cameras=inputs.cameras,
        gt_associations=inputs.gt_associations, gt_poses3d=inputs.gt_poses3d, gt_cameras=inputs.gt_cameras,
        failed_checks=failed, gt_cameras_association=inputs.gt_cameras_association)


def _body_rows(spec, inputs: MethodInputs, config: BodyFitSettings, body_model: BodyModelResource,
               fitted_motions: pd.DataFrame, refined_cameras: pd.DataFrame, gt_motions: pd.DataFrame,
               run_records: pd.DataFrame, failed: str) -> pd.DataFrame:
    """The pipeline's fitted bodies and refined cameras (``int_ext`` rows) and the skeletons' rows."""
    return pipeline_body_table(
        spec, body=body_model.get(), regime=body_fit_regime(spec, config.cameras), fps=sequence_fps(spec)[0],
        fitted_motions=fitted_motions, refined_cameras=cameras_from_table(refined_cameras),
        fit_seconds=stage_seconds(run_records, "fitted_motions"), associations=inputs.associations,
        skeletons3d=inputs.skeletons3d, lifted_detections=inputs.detections, detections=inputs.raw_detections,
        cameras=inputs.cameras, gt_associations=inputs.gt_associations, gt_poses3d=inputs.gt_poses3d,
        gt_cameras=inputs.gt_cameras, gt_motions=gt_motions, failed_checks=failed,
        gt_cameras_association=inputs.gt_cameras_association)


def _rig_pictures(key: str, estimated: CameraRig, refined_cameras: pd.DataFrame, gt: CameraRig,
                  raw_detections: pd.DataFrame, gt_associations: pd.DataFrame, regime: str) -> dict:
    """The estimated (and the refined) rig aligned to the true one, as metadata pictures."""
    pictures = {}
    with tempfile.TemporaryDirectory() as tmp:
        png = plot_rig_comparison(estimated, gt, raw_detections, gt_associations, Path(tmp) / "rigs.png",
                                  title=f"{key}: initial cameras (aligned) and ground truth")
        pictures["rigs"] = png_metadata(png, "camera rigs")
        if len(refined_cameras):
            png = plot_rig_comparison(cameras_from_table(refined_cameras), gt, raw_detections, gt_associations,
                                      Path(tmp) / "refined_rigs.png",
                                      title=f"{key}: refined cameras ({regime}, aligned) and ground truth")
            pictures["refined_rigs"] = png_metadata(png, "refined camera rigs")
    return pictures


def camera_checks_of(run_records: pd.DataFrame, log) -> str:
    """The checks the cameras of ``extrinsics`` failed, as ``run_records`` holds them ("" if none; cameras whose
    checks were never recorded are marked ``unchecked`` rather than pass); ``log`` (a Dagster logger) warns."""
    failed = failed_checks(run_records)
    if failed == UNCHECKED:
        log.warning("the checks of the extrinsics read here were not recorded: camera rows marked unchecked")
    elif failed:
        log.warning(f"camera rows computed from cameras that failed {failed.replace(',', ', ')}")
    return failed
