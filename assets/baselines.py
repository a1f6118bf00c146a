"""Reference reconstructions that are allowed ground truth (cameras, identities)."""


import dagster as dg
import pandas as pd
import threadpoolctl

from assets.common import UPDATE_CONDITION, sequence_asset, table_metadata, table_output
from assets.partitions import SEQUENCES
from evaluation.association_metrics import associate_tables
from humancal.baselines import triangulate_identified
from humancal.camera import cameras_from_table
from humancal.lifter import lifted_from_table
from humancal.tables.schemas import empty_table
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


_GT_CAMERA_OUTPUTS = {
    "gt_camera_associations": ("associations", "Evaluation only: who is who when the association is given the "
                                               "true cameras (the pipeline's association, perfect calibration)."),
    "gt_camera_skeletons3d": ("skeletons3d", "Evaluation only: the 3D skeletons of that association, in the true "
                                             "cameras' world frame, metres."),
}


@dg.multi_asset(
    outs={name: dg.AssetOut(description=desc, metadata=table_metadata(table), code_version="1",
                            automation_condition=UPDATE_CONDITION)
          for name, (table, desc) in _GT_CAMERA_OUTPUTS.items()},
    partitions_def=SEQUENCES,
    group_name="sequence",
)
def gt_camera_association(context: dg.AssetExecutionContext, datasets: DatasetsResource, detections: pd.DataFrame,
                          gt_cameras: pd.DataFrame, gt_associations: pd.DataFrame, gt_poses3d: pd.DataFrame):
    """Reference: the pipeline's association (default settings) run with the true cameras, for the metric rows
    ``association_gt_cameras`` and ``skeletons3d_gt_cameras``; empty tables where the sequence has no true cameras,
    identities or 3D poses to score it against."""
    spec = datasets.spec(context.partition_key)
    cameras = cameras_from_table(gt_cameras)
    if not cameras or gt_associations.empty or gt_poses3d.empty:
        context.log.info(f"{spec.key}: nothing to score an association with the true cameras against: empty tables")
        people, skeletons, seconds = empty_table("associations"), empty_table("skeletons3d"), float("nan")
    else:
        dense, lifted = lifted_from_table(detections)
        with threadpoolctl.threadpool_limits(1):  # many small per-frame solves, as in the association asset
            people, skeletons, seconds = associate_tables(dense, lifted, cameras, spec.sequence)
    yield table_output(people, "associations", output_name="gt_camera_associations", rows=len(people),
                       seconds_total=round(seconds, 3))
    yield table_output(skeletons, "skeletons3d", output_name="gt_camera_skeletons3d", rows=len(skeletons))
