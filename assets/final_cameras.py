"""Per sequence: the cameras a run ends with, the ones ``humancal export cameras`` and the reports take."""

import dagster as dg
import pandas as pd

from assets.checks import check_result
from assets.common import sequence_asset, table_output
from humancal.calibration.final import choose_final_cameras
from humancal.camera import CameraRig, cameras_by_view, with_known_distortion
from humancal.lifter import lifted_from_table
from humancal.tables.associations import Associations
from humancal.tables.plausibility import check_views_agree


@sequence_asset(
    "cameras",
    code_version="2",
    check_specs=[dg.AssetCheckSpec("views_agree", asset="final_cameras", blocking=True,
                                   description="every view of the final cameras agrees with the people the other "
                                               "views triangulate (the association's people)")],
)
def final_cameras(context: dg.AssetExecutionContext, detections: pd.DataFrame, associations: pd.DataFrame,
                  views: pd.DataFrame, extrinsics: pd.DataFrame, refined_cameras: pd.DataFrame,
                  known_cameras: pd.DataFrame):
    """The refined cameras when the refinement ran and every view of them agrees with the people the others
    triangulate, else the calibration's (``extrinsics``); the table's metadata says which. Known cameras get
    their lens distortion back (the method used them as pinholes on undistorted detections)."""
    dense, _ = lifted_from_table(detections)
    person = Associations.from_table(associations).person_of_detections(dense)
    choice = choose_final_cameras(CameraRig.from_table(extrinsics),
                                  CameraRig.from_table(refined_cameras) if len(refined_cameras) else None,
                                  dense, person)
    context.log.info(f"final cameras: {choice.source} ({choice.reason})")
    names = views.sort_values("view")["name"].astype(str).tolist() if "name" in views.columns else None
    rig = with_known_distortion(choice.rig, cameras_by_view(known_cameras)) if len(known_cameras) else choice.rig
    table = rig.to_table(context.partition_key)
    yield table_output(table, "cameras", rows=len(table), source=choice.source, reason=choice.reason,
                       per_view=dg.MetadataValue.md(choice.agreement.to_markdown(index=False, floatfmt=".3g")))
    yield check_result(context, "views_agree", check_views_agree(choice.per_view, names))
