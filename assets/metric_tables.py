"""Per sequence: every method's figures against the ground truth, in one metrics table."""


import dagster as dg
import pandas as pd

from assets.common import sequence_asset, table_output
from evaluation.sequence_metrics import sequence_metric_table
from humancal.camera import cameras_from_table
from resources.datasets import DatasetsResource


@sequence_asset("metrics", code_version="2")
def metric_tables(
    context: dg.AssetExecutionContext,
    datasets: DatasetsResource,
    gt_camera_triangulation: pd.DataFrame,
    raw_detections: pd.DataFrame,
    gt_cameras: pd.DataFrame,
    gt_poses3d: pd.DataFrame,
    gt_associations: pd.DataFrame,
) -> dg.Output:
    """MPJPE, PCP and reprojection error of each method; detection grouping quality on real datasets."""
    spec = datasets.spec(context.partition_key)
    table = sequence_metric_table(
        spec,
        gt_camera_triangulation=gt_camera_triangulation,
        detections=raw_detections,
        associations=gt_associations,
        cameras=cameras_from_table(gt_cameras),
        gt_poses3d=gt_poses3d,
    )
    headline = table[~table["metric"].str.contains("/")]
    context.log.info(f"{spec.key}: {len(table)} metric rows ({len(headline)} headline)")
    return table_output(
        table, "metrics", rows=len(table),
        summary=dg.MetadataValue.md(headline.to_markdown(index=False, floatfmt=".2f")),
    )
