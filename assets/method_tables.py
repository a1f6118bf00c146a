"""Per sequence, on request: the other regimes of the paper's Tables fitted on the pipeline's detections and
association (``evaluation.method_comparison``), for the benchmark table. Several full fits: ``humancal update``
leaves it alone; ``humancal benchmark`` computes it."""

import dagster as dg
import pandas as pd

from assets.common import ON_REQUEST_KEY, table_metadata, table_output
from assets.metric_tables import camera_checks_of
from assets.motion_prior import prior_from_checkpoint
from assets.partitions import SEQUENCES
from assets.settings import BodyFitSettings
from evaluation.method_comparison import METHODS, method_metric_table
from humancal.camera import cameras_from_table
from humancal.datasets.inputs import sequence_fps
from humancal.lifter import lifted_from_table
from humancal.prior import shipped_prior
from humancal.prior.weights import PriorWeightsError
from humancal.tables.schemas import empty_table
from resources.body_model import BodyModelResource
from resources.datasets import DatasetsResource
from resources.prior_source import FIT_VARIANT
from resources.torch import TorchResource

DEFAULT_METHODS = [m for m in METHODS if m != "int_ext"]
"""Every regime but the pipeline's own (``int_ext``, already in ``metric_tables``)."""


class MethodTableSettings(BodyFitSettings):
    """The body fit's settings (the same as ``fitted_motions``'s: give both the same run config) and the methods."""

    methods: list[str] = DEFAULT_METHODS

    def to_library(self):
        return BodyFitSettings(**self.model_dump(exclude={"methods"})).to_library()


def _priors(fit_checkpoint: dict):
    """The priors by variant: the one in force for the fit's own variant, the shipped ablations (None where none
    ships)."""
    fit_prior = prior_from_checkpoint(fit_checkpoint)

    def prior(variant: str):
        if variant == FIT_VARIANT:
            return fit_prior
        try:
            return shipped_prior(variant)[0]
        except PriorWeightsError:
            return None

    return prior


@dg.asset(
    partitions_def=SEQUENCES,
    group_name="benchmark",
    metadata={**table_metadata("metrics"), ON_REQUEST_KEY: "humancal benchmark"},
    code_version="12",
    description="The paper's regimes (ext, gt_cameras, init, separate, per_frame_prior, no_prior and the prior "
                "ablations whose weights exist), and int_ext with the true principal points (a diagnostic), fitted "
                "and scored on one sequence; convention_floor: the cameras the self-calibration's convention allows "
                "at best (a diagnostic, no fit).",
)
def method_tables(context: dg.AssetExecutionContext, config: MethodTableSettings, datasets: DatasetsResource,
                  body_model: BodyModelResource, torch_runtime: TorchResource, raw_detections: pd.DataFrame,
                  detections: pd.DataFrame, extrinsics: pd.DataFrame, gt_cameras: pd.DataFrame,
                  gt_poses3d: pd.DataFrame, gt_associations: pd.DataFrame, associations: pd.DataFrame,
                  skeletons3d: pd.DataFrame, gt_motions: pd.DataFrame, motion_prior_checkpoint: dict,
                  run_records: pd.DataFrame) -> dg.Output:
    """Fit every method of ``config.methods`` (``evaluation.method_comparison.METHODS``) and score it."""
    unknown = sorted(set(config.methods) - set(METHODS))
    if unknown:
        raise dg.Failure(f"method_tables: unknown method(s) {unknown}; known: {list(METHODS)}")
    spec = datasets.spec(context.partition_key)
    gt = cameras_from_table(gt_cameras)
    if not gt or len(gt_associations) == 0 or len(gt_poses3d) == 0:
        context.log.info(f"{spec.key}: no known cameras, identities or 3D poses: no method rows")
        return table_output(empty_table("metrics"), "metrics", rows=0)
    failed = camera_checks_of(run_records, context.log)
    dense, lifted = lifted_from_table(detections)
    with torch_runtime.applied():
        table = method_metric_table(
            spec, methods=list(config.methods), priors=_priors(motion_prior_checkpoint), body=body_model.get(),
            config=config.to_library(), fps=sequence_fps(spec)[0], dense=dense, lifted=lifted,
            detections=raw_detections, associations=associations, skeletons3d=skeletons3d,
            cameras=cameras_from_table(extrinsics), gt_associations=gt_associations, gt_poses3d=gt_poses3d,
            gt_cameras=gt, gt_motions=gt_motions, failed_checks=failed, log=context.log.info)
    if table.empty:
        table = empty_table("metrics")
    headline = table[table["view"].isna()].drop(columns="view")
    return table_output(table, "metrics", rows=len(table), methods=", ".join(sorted(set(table["method"]))),
                        summary=dg.MetadataValue.md(headline.pivot_table(
                            index="method", columns="metric", values="value", aggfunc="first").to_markdown(
                            floatfmt=".2f")) if len(headline) else "no rows")
