"""The one Definitions object of humancal (``dagster dev`` / ``dagster asset materialize`` load it)."""

from __future__ import annotations

import dagster as dg

from assets.association import association
from assets.baselines import gt_camera_association, gt_camera_triangulation
from assets.benchmark import build_benchmark_assets
from assets.bodies import body_fit
from assets.calibration import detections, extrinsics, intrinsics
from assets.final_cameras import final_cameras
from assets.lifter import build_lifter_assets
from assets.method_tables import method_tables
from assets.metric_tables import metric_tables
from assets.mocap import mocap_clips
from assets.motion_prior import PriorEvaluationSettings, build_motion_prior_assets
from assets.registry import sequence_registry
from assets.run_records import run_records
from assets.sequence_inputs import sequence_inputs
from humancal.lifter import LifterConfig
from humancal.prior import PriorConfig
from humancal.settings import state_dir
from pipelines.prior_automation import build_mocap_change_sensor, build_weekly_prior_schedule, prior_training_job
from pipelines.sensors import capture_inbox
from resources.body_model import BodyModelResource
from resources.datasets import DatasetsResource
from resources.io_managers import CheckpointIOManagerFactory, ParquetIOManagerFactory
from resources.torch import TorchResource

PER_SEQUENCE_ASSETS = [sequence_inputs, gt_camera_triangulation, gt_camera_association, detections, intrinsics,
                       extrinsics, association, body_fit, final_cameras, run_records, metric_tables,
                       method_tables]
"""Assets partitioned by sequence (select them with ``--select 'group:sequence'``)."""

SHARED_ASSETS = [sequence_registry, mocap_clips]
"""Unpartitioned assets (besides the lifter's, which depend on its training configuration)."""


def artifacts_root() -> str:
    """Default storage root of every artifact: ``<state dir>/artifacts``."""
    return str(state_dir() / "artifacts")


def build_definitions(
    storage_root: str | None = None,
    lifter_config: LifterConfig | None = None,
    datasets: DatasetsResource | None = None,
    prior_configs: dict[str, PriorConfig] | None = None,
    prior_evaluation: PriorEvaluationSettings | None = None,
) -> dg.Definitions:
    """Definitions with artifacts under ``storage_root`` (default: :func:`artifacts_root`).

    Args:
        storage_root: artifact folder or fsspec URL.
        lifter_config: training configuration of ``lifter_trained`` (default :meth:`LifterConfig.default`, the
            configuration of the shipped weights; tests use a small one).
        datasets: the datasets resource (default: the packaged config and ``HUMANCAL_DATA_DIR``).
        prior_configs: training configuration of ``motion_prior_trained`` by variant (default: each variant's
            :meth:`PriorConfig.default`; tests use tiny ones).
        prior_evaluation: size of the held-out benchmark of ``prior_metrics`` (tests use a small one).
    """
    root = storage_root or artifacts_root()
    lifter_assets = build_lifter_assets(lifter_config or LifterConfig.default(), root)
    lifter_training = dg.define_asset_job(
        "lifter_training_job", selection=dg.AssetSelection.assets("mocap_clips", "lifter_trained"),
        description="Retarget the CMU mocap of the data root and train the lifter on it (it then replaces the "
                    "shipped weights; `humancal update` re-lifts every sequence with it).")
    prior_assets = build_motion_prior_assets(prior_configs, prior_evaluation, storage_root=root)
    prior_training = prior_training_job()
    return dg.Definitions(
        # benchmark_table, stage_timings (group benchmark_summary): unpartitioned, read every partition's tables
        assets=[*SHARED_ASSETS, *lifter_assets, *prior_assets, *PER_SEQUENCE_ASSETS,
                *build_benchmark_assets(PER_SEQUENCE_ASSETS)],
        jobs=[
            dg.define_asset_job("sequence_job", selection=dg.AssetSelection.groups("sequence"),
                                description="Every per-sequence asset of one partition."),
            lifter_training,
            prior_training,
        ],
        schedules=[
            dg.ScheduleDefinition(
                name="weekly_lifter_retraining", job=lifter_training, cron_schedule="0 3 * * 0",
                default_status=dg.DefaultScheduleStatus.STOPPED,
                description="Sundays 03:00: retrain the lifter on the mocap under the data root (turn on in the UI).",
            ),
            build_weekly_prior_schedule(prior_training),
        ],
        sensors=[capture_inbox, build_mocap_change_sensor(prior_training)],
        resources={
            "io_manager": ParquetIOManagerFactory(base_path=root),
            "checkpoint_io_manager": CheckpointIOManagerFactory(base_path=root),
            "body_model": BodyModelResource(),
            "datasets": datasets or DatasetsResource(),
            "torch_runtime": TorchResource(),
        },
    )


defs = build_definitions()
