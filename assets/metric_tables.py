"""Per sequence: every method's figures against the ground truth, in one metrics table."""

import tempfile
from pathlib import Path

import dagster as dg
import pandas as pd

from assets.common import png_metadata, sequence_asset, table_output
from evaluation.camera_metrics import camera_metrics_table
from evaluation.lifter_metrics import lifter_metrics_table
from evaluation.rig_plot import plot_rig_comparison
from evaluation.sequence_metrics import sequence_metric_table
from humancal.camera import cameras_from_table
from resources.datasets import DatasetsResource


@sequence_asset("metrics", code_version="4")
def metric_tables(
    context: dg.AssetExecutionContext,
    datasets: DatasetsResource,
    gt_camera_triangulation: pd.DataFrame,
    raw_detections: pd.DataFrame,
    detections: pd.DataFrame,
    extrinsics: pd.DataFrame,
    gt_cameras: pd.DataFrame,
    gt_poses3d: pd.DataFrame,
    gt_associations: pd.DataFrame,
    gt_people: pd.DataFrame,
) -> dg.Output:
    """MPJPE, PCP and reprojection error of each method; the lifter's 3D and height errors; the camera
    initialisation's focal, position, angle and reprojection errors; detection grouping on real datasets."""
    spec = datasets.spec(context.partition_key)
    gt = cameras_from_table(gt_cameras)
    estimated = cameras_from_table(extrinsics)
    table = pd.concat(
        [
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
            camera_metrics_table(spec.dataset, spec.sequence, estimated, gt, raw_detections, gt_associations),
        ],
        ignore_index=True,
    )
    headline = table[table["view"].isna() & ~table["metric"].str.contains("/")].drop(columns="view")
    context.log.info(f"{spec.key}: {len(table)} metric rows ({len(headline)} headline)")
    with tempfile.TemporaryDirectory() as tmp:
        png = plot_rig_comparison(estimated, gt, raw_detections, gt_associations, Path(tmp) / "rigs.png",
                                  title=f"{spec.key}: initial cameras (aligned) and ground truth")
        rigs = png_metadata(png, "camera rigs")
    return table_output(
        table, "metrics", rows=len(table), rigs=rigs,
        summary=dg.MetadataValue.md(headline.to_markdown(index=False, floatfmt=".2f")),
    )
