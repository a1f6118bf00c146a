"""Reference reconstructions that are allowed ground truth (cameras, identities)."""


import dagster as dg
import pandas as pd

from assets.common import sequence_asset, table_output
from humancal.baselines import triangulate_identified
from humancal.camera import cameras_from_table
from humancal.tables import empty_table
from resources.datasets import DatasetsResource


@sequence_asset("poses3d", code_version="1")
def gt_camera_triangulation(
    context: dg.AssetExecutionContext,
    datasets: DatasetsResource,
    raw_detections: pd.DataFrame,
    gt_cameras: pd.DataFrame,
    gt_associations: pd.DataFrame,
) -> dg.Output:
    """Baseline: ground-truth cameras and identities, confidence-weighted DLT per person and frame."""
    spec = datasets.spec(context.partition_key)
    if gt_cameras.empty or gt_associations.empty:
        what = "known cameras" if gt_cameras.empty else "ground-truth identities"
        context.log.info(f"{spec.key}: no {what}: no reference reconstruction (empty poses3d table)")
        return table_output(empty_table("poses3d"), "poses3d", rows=0, valid_joints=0)
    poses = triangulate_identified(raw_detections, gt_associations, cameras_from_table(gt_cameras), spec.sequence)
    context.log.info(f"{spec.key}: triangulated {int(poses['valid'].sum())} joints of {poses.groupby(['frame', 'person_id']).ngroups} person-frames")
    return table_output(poses, "poses3d", rows=len(poses), valid_joints=int(poses["valid"].sum()))
