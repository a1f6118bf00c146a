"""Per sequence: the raw inputs and the ground truth, loaded or generated in one step."""


import tempfile
from pathlib import Path

import dagster as dg

from assets.checks import check_result
from assets.common import UPDATE_CONDITION, png_metadata, table_metadata, table_output
from assets.partitions import SEQUENCES
from humancal.datasets.inputs import load_sequence_inputs
from humancal.tables.plausibility import check_cameras_valid, check_detections_plausible
from humancal.viewing.pictures import plot_detections_over_time
from resources.body_model import BodyModelResource
from resources.datasets import DatasetsResource

# output name -> (canonical table, SequenceInputs attribute, description)
_OUTPUTS = {
    "raw_detections": ("detections", "detections", "2D detections in the canonical 23 keypoints, no identities."),
    "views": ("views", "views", "Image size of every view."),
    "gt_cameras": ("cameras", "gt_cameras", "Ground-truth cameras (evaluation only)."),
    "known_cameras": ("cameras", "known_cameras", "Cameras the capture brings for the method to use (the known views "
                                                  "only; empty: every camera is calibrated from the people)."),
    "gt_poses3d": ("poses3d", "gt_poses3d", "Ground-truth 3D joints in the world frame (evaluation only)."),
    "gt_associations": ("associations", "gt_associations", "Ground-truth person id of each detection (evaluation only)."),
    "gt_people": ("people", "gt_people", "Ground-truth body shape of each person (empty where unknown)."),
    "gt_motions": ("motions", "gt_motions", "Ground-truth body-model motions (synthetic scenes; empty where unknown; "
                                            "evaluation only)."),
}
CODE_VERSION = "2"


def _detections_notes(inputs) -> dict:
    """The raw detections' metadata: the loader's notes and the picture of who each view saw over time."""
    names = inputs.views.sort_values("view")["name"].astype(str).tolist()
    with tempfile.TemporaryDirectory() as tmp:
        picture = png_metadata(plot_detections_over_time(inputs.detections, names, Path(tmp) / "detections.png"),
                               "people detected per view over time")
    return {**inputs.detections_notes, "picture": picture}


@dg.multi_asset(
    outs={
        name: dg.AssetOut(
            description=desc,
            metadata=table_metadata(table),
            code_version=CODE_VERSION,
            automation_condition=UPDATE_CONDITION,
            is_required=False,
        )
        for name, (table, _, desc) in _OUTPUTS.items()
    },
    check_specs=[
        dg.AssetCheckSpec("detections_plausible", asset="raw_detections", blocking=True,
                          description="finite, inside the image (10% margin), scores in [0, 1]"),
        dg.AssetCheckSpec("cameras_valid", asset="gt_cameras", blocking=True,
                          description="finite positive focal, principal point inside, proper rotation"),
    ],
    partitions_def=SEQUENCES,
    can_subset=True,
    group_name="sequence",
)
def sequence_inputs(context: dg.AssetExecutionContext, body_model: BodyModelResource, datasets: DatasetsResource):
    """Load (real datasets) or generate (synthetic) the inputs of one sequence."""
    spec = datasets.spec(context.partition_key)
    inputs = load_sequence_inputs(spec, body_model.get, datasets.root())
    context.log.info(
        f"{spec.key}: {inputs.detections.groupby(['frame', 'view', 'det_id']).ngroups} detections in "
        f"{len(inputs.views)} views, {inputs.detections['frame'].nunique()} frames"
    )
    for name in sorted(key.path[-1] for key in context.selected_asset_keys):
        table, attr, _ = _OUTPUTS[name]
        df = getattr(inputs, attr)
        notes = _detections_notes(inputs) if name == "raw_detections" else {}
        yield table_output(df, table, output_name=name, rows=len(df), **notes)
    selected_checks = {key.name for key in context.selected_asset_check_keys}
    if "detections_plausible" in selected_checks:
        report = check_detections_plausible(inputs.detections, inputs.views)
        yield check_result(context, "detections_plausible", report, asset_key="raw_detections")
    if "cameras_valid" in selected_checks:
        # own captures have no ground-truth cameras: "not checked" (a warning), not a pass
        report = check_cameras_valid(inputs.gt_cameras)
        yield check_result(context, "cameras_valid", report, asset_key="gt_cameras")
