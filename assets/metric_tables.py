"""Per sequence: every method's figures against the ground truth, in one metrics table."""

import tempfile
from pathlib import Path

import dagster as dg
import pandas as pd

from assets.association import latest_association_seconds
from assets.baselines import gt_camera_association_seconds
from assets.bodies import latest_fit_seconds
from assets.settings import BodyFitSettings
from assets.checks import latest_check_outcomes
from assets.common import png_metadata, sequence_asset, table_output
from evaluation.association_metrics import association_metric_table
from evaluation.body_metrics import PIPELINE_METHOD, pipeline_body_table
from evaluation.camera_metrics import camera_metrics_table
from evaluation.lifter_metrics import lifter_metrics_table
from evaluation.rig_plot import plot_rig_comparison
from evaluation.sequence_metrics import sequence_metric_table
from humancal.camera import cameras_from_table
from humancal.inputs import body_fit_regime, sequence_fps
from humancal.lifter import lifted_from_table
from humancal.tables import empty_table
from resources.body_model import BodyModelResource
from resources.datasets import DatasetsResource
from resources.torch import TorchResource


@sequence_asset("metrics", code_version="17")
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
) -> dg.Output:
    """MPJPE, PCP and reprojection error of each method; the lifter's 3D and height errors; the camera
    initialisation's focal, position, angle and reprojection errors; detection grouping on real datasets; who is
    who; the pipeline's fitted bodies and refined cameras (method ``int_ext`` with the default settings) against the
    triangulated skeletons (``evaluation.body_metrics``; ``config`` must be the body fit's: it names the regime).
    The other regimes of the paper's Tables are fitted by ``method_tables`` (on request).
    The camera rows name the checks of ``extrinsics`` that its cameras failed (column ``failed_checks``)."""
    spec = datasets.spec(context.partition_key)
    gt = cameras_from_table(gt_cameras)
    estimated = cameras_from_table(extrinsics)
    # A user's capture may come without known cameras, identities or 3D poses: only the rows its ground truth
    # supports (camera errors need known cameras; everything else needs identities and poses too).
    identified = bool(gt) and len(gt_associations) > 0 and len(gt_poses3d) > 0
    parts = []
    if identified:
        parts += [
            sequence_metric_table(
                spec,
                gt_camera_triangulation=gt_camera_triangulation,
                detections=raw_detections,
                associations=gt_associations,
                cameras=gt,
                gt_poses3d=gt_poses3d,
            ),
            lifter_metrics_table(spec.dataset, spec.sequence, detections, gt_associations, gt_poses3d, gt_cameras,
                                 gt_people),
        ]
    if gt:
        failed = failed_camera_checks(context)
        parts.append(camera_metrics_table(spec.dataset, spec.sequence, estimated, gt,
                                          raw_detections if identified else None, gt_associations if identified else None,
                                          failed_checks=failed))
        if not identified and len(refined_cameras):  # a capture with reference cameras: the refined rig's rows too
            parts.append(camera_metrics_table(spec.dataset, spec.sequence, cameras_from_table(refined_cameras), gt,
                                              method=PIPELINE_METHOD[body_fit_regime(spec, config.cameras)],
                                              failed_checks=failed))
        if identified:  # who is who, against the true identities (the association itself never reads them)
            # the association with the true cameras (evaluation only; asset gt_camera_association)
            dense, lifted = lifted_from_table(detections)
            with_true_cameras = (gt_camera_associations, gt_camera_skeletons3d,
                                 gt_camera_association_seconds(context.instance, context.partition_key))
            parts.append(association_metric_table(
                spec, associations=associations, skeletons3d=skeletons3d,
                seconds=latest_association_seconds(context.instance, context.partition_key),
                dense=dense, lifted=lifted, cameras=estimated, gt_associations=gt_associations,
                gt_poses3d=gt_poses3d, gt_cameras=gt, failed_checks=failed, gt_cameras_association=with_true_cameras))
            with torch_runtime.applied():
                parts.append(pipeline_body_table(
                    spec, body=body_model.get(), regime=body_fit_regime(spec, config.cameras), fps=sequence_fps(spec)[0],
                    fitted_motions=fitted_motions, refined_cameras=cameras_from_table(refined_cameras),
                    fit_seconds=latest_fit_seconds(context.instance, context.partition_key),
                    associations=associations, skeletons3d=skeletons3d, lifted_detections=detections,
                    detections=raw_detections, cameras=estimated, gt_associations=gt_associations,
                    gt_poses3d=gt_poses3d, gt_cameras=gt, gt_motions=gt_motions, failed_checks=failed,
                    gt_cameras_association=with_true_cameras))
    else:
        context.log.info(f"{spec.key}: no known cameras: no metric rows (the calibrated cameras are in extrinsics)")
    table = pd.concat(parts, ignore_index=True) if parts else empty_table("metrics")
    headline = table[table["view"].isna() & ~table["metric"].str.contains("/")].drop(columns="view")
    context.log.info(f"{spec.key}: {len(table)} metric rows ({len(headline)} headline)")
    pictures = {}
    if gt:
        with tempfile.TemporaryDirectory() as tmp:
            png = plot_rig_comparison(estimated, gt, raw_detections, gt_associations, Path(tmp) / "rigs.png",
                                      title=f"{spec.key}: initial cameras (aligned) and ground truth")
            pictures["rigs"] = png_metadata(png, "camera rigs")
            if len(refined_cameras):
                png = plot_rig_comparison(cameras_from_table(refined_cameras), gt, raw_detections, gt_associations,
                                          Path(tmp) / "refined_rigs.png",
                                          title=f"{spec.key}: refined cameras ({config.cameras}, aligned) and ground truth")
                pictures["refined_rigs"] = png_metadata(png, "refined camera rigs")
    return table_output(
        table, "metrics", rows=len(table), **pictures,
        summary=dg.MetadataValue.md(headline.to_markdown(index=False, floatfmt=".2f")),
    )


def failed_camera_checks(context: dg.AssetExecutionContext) -> str:
    """The checks that the cameras of ``extrinsics`` in this partition failed, comma-separated ("" if none).

    Read from the checks of its latest materialization (the cameras this asset reads); cameras whose checks were
    never recorded (materialized without them) say so rather than pass.
    """
    outcomes = latest_check_outcomes(context.instance, dg.AssetKey("extrinsics"), context.partition_key)
    if not outcomes:
        context.log.warning("the checks of the extrinsics read here were not recorded: camera rows marked unchecked")
        return "unchecked"
    failed = sorted(o.check for o in outcomes if not o.passed)
    if failed:
        context.log.warning(f"camera rows computed from cameras that failed {', '.join(failed)}")
    return ",".join(failed)
