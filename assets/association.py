"""Per sequence: who is who (the person of every detection, from the calibrated cameras) and the people's 3D
skeletons, without ground truth (the paper's III-C; ``docs/association.md``)."""

import tempfile
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd
import threadpoolctl

from assets.common import UPDATE_CONDITION, png_metadata, table_metadata, table_output
from assets.partitions import SEQUENCES
from assets.settings import AssociationSettings
from humancal.association import associate, to_associations_table, to_skeletons_table
from humancal.association.plot import plot_association
from humancal.camera import CameraRig
from humancal.lifter import lifted_from_table

CODE_VERSION = "4"

_OUTPUTS = {
    "associations": ("associations", "The person id of every detection (-1: rejected as a false positive), matched "
                                     "across views and tracked over time with the calibrated cameras."),
    "skeletons3d": ("skeletons3d", "The triangulated 3D joints of every person and frame, in the calibrated "
                                   "cameras' world frame, metres."),
}


@dg.multi_asset(
    outs={
        name: dg.AssetOut(description=desc, metadata=table_metadata(table), code_version=CODE_VERSION,
                          automation_condition=UPDATE_CONDITION)
        for name, (table, desc) in _OUTPUTS.items()
    },
    partitions_def=SEQUENCES,
    group_name="sequence",
)
def association(context: dg.AssetExecutionContext, config: AssociationSettings, detections: pd.DataFrame,
                extrinsics: pd.DataFrame):
    """Affinities of the lifted detections of each frame, cycle-consistent matching across views, tracking over
    time, triangulation: from the self-calibrated cameras and the detections alone (never ground truth)."""
    dense, lifted = lifted_from_table(detections)
    rig = CameraRig.from_table(extrinsics)
    # many small per-frame solves: multi-threaded BLAS only adds overhead (as in the calibration)
    with threadpoolctl.threadpool_limits(1):
        result = associate(dense, lifted, rig, config.to_library())
    for warning in result.warnings:
        context.log.warning(warning)
    sequence = context.partition_key
    people = to_associations_table(result, sequence)
    skeletons = to_skeletons_table(result, sequence)
    seconds = {f"seconds_{stage}": round(float(s), 3) for stage, s in result.stage_seconds.items()}
    rejected = int((result.person_id < 0).sum())
    with tempfile.TemporaryDirectory() as tmp:
        png = plot_association(result, dense, rig, Path(tmp) / "association.png",
                               title=f"{sequence}: {result.num_people} people, {rejected} detections rejected")
        picture = png_metadata(png, "person ids over time and one frame of the views")
    context.log.info(f"{sequence}: {result.num_people} people, {len(people) - rejected} of {len(people)} detections "
                     f"associated in {result.stage_seconds.get('total', float('nan')):.2f} s")
    yield table_output(people, "associations", output_name="associations", rows=len(people),
                       num_people=int(result.num_people), rejected_detections=rejected, picture=picture,
                       **seconds)
    yield table_output(skeletons, "skeletons3d", output_name="skeletons3d", rows=len(skeletons),
                       num_people=int(result.num_people), skeletons=int(len(result.skeleton_frame)),
                       valid_joint_fraction=float(np.mean(skeletons["valid"])) if len(skeletons) else 0.0)
